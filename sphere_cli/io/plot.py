"""`sphere plot RUN_DIR`: PNG figures of a run (matplotlib, the `plot` extra), each drawn when
the run recorded what it needs, every axis labelled with its unit.

The headline result of each kind of run:
  strain.png       experiments with stages: stress ratio and dilation against strain (shear
                   strain in direct shear, else axial strain), the stages shaded, from the end of
                   the first (preparation) stage
  pore_pressure.png  Darcy: pore pressure against depth at a few times, and against time at a
                   few depths (horizontal means)
  bedload_profiles.png, bedload_series.png  1D VANS: fluid velocity, solid fraction and sediment
                   flux density against height; Shields number and dimensionless flux Q* in time
  fluid_slices.png Navier-Stokes: pressure and velocity in the vertical x-z plane through the
                   middle of the box, last frame
Time series of the observables:
  stress.png       pressure, sigma_zz and the shear traction tau = -sigma_zx (or -sigma_zy) [Pa]
  friction.png     effective friction tau/sigma_n [-]
  deformation.png  dilation [-] and sample height [m]
  energy.png       kinetic, elastic, potential energy; with the budget, the work of gravity and
                   walls, the dissipated energies and the balance residual [J]
  structure.png    packing fractions [-] and coordination numbers [-], on two axes
Profiles against height at the last sample (and a few earlier ones):
  profiles.png     solid fraction, sigma_zz, shear stress and mean velocity per layer
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from ..errors import MissingDependency, MissingInputError, OutputError
from .trajectory import not_an_output, open_to_read

INSTALL_HINT = "pip install 'sphere-cli[plot]'"

SERIES = {
    "stress": ("stress [Pa]", ["pressure", "stress_zz", "stress_shear"]),
    "friction": ("effective friction tau/sigma_n [-]", ["effective_friction"]),
    "deformation": ("", ["dilation", "sample_height"]),
    "energy": (
        "energy [J]",
        [
            "kinetic_energy",
            "elastic_energy",
            "potential_energy",
            "work_gravity",
            "work_walls",
            "energy_change",
            "dissipated_damping",
            "dissipated_friction",
            "dissipated_rolling",
            "energy_balance_residual",
        ],
    ),
}
STRUCTURE = (
    ("packing fraction [-]", ["packing_fraction", "packing_fraction_interior"]),
    ("coordination number [-]", ["coordination", "coordination_no_rattlers"]),
)


def _pyplot():
    try:
        import matplotlib
    except ImportError:
        raise MissingDependency(
            f"sphere plot needs matplotlib, which is not installed; install it with: {INSTALL_HINT}"
        ) from None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _read(trajectory: Path) -> tuple[dict, str, dict]:
    """name -> (time (S,), value (S, ...), unit) (and "wall_faces": the faces of the wall series'
    rows), the shear axis letter, and the fluid: {"model", "time" (frames,) of its fields, and
    its fields by name as (value, unit): on a 3D grid ("origin", "spacing", "shape" (nx, ny, nz)
    too) the grid fields (frames, nz, ny, nx[, 3]), in a column of layers the profiles
    (frames, layers)}, or {} without a fluid."""
    try:
        with open_to_read(trajectory) as f:
            series = {}
            for name, group in f["observables"].items():
                unit = group["value"].attrs.get("unit", "")
                series[name] = (group["time"][...], group["value"][...], str(unit))
            if "wall_faces" in f["observables"].attrs:  # the order of the rows of the wall series
                series["wall_faces"] = [face.decode() for face in f["observables"].attrs["wall_faces"]]
            resolved = json.loads(f["parameters"].attrs["resolved_case"])
            fluid = _read_fluid(f)
    except (OSError, KeyError) as exc:
        reason = f"not a readable sphere trajectory ({exc})"
        raise not_an_output(trajectory, reason, "a run directory or its trajectory.h5") from None
    shear = resolved.get("output", {}).get("observables", {}).get("shear_direction", "x")
    if "stress" in series:
        t, sigma, unit = series["stress"]
        a = "xyz".index(shear)
        series["stress_zz"] = (t, sigma[:, 2, 2], unit)
        series["stress_shear"] = (t, -0.5 * (sigma[:, 2, a] + sigma[:, a, 2]), unit)
    return series, shear, fluid


def _read_fluid(f: h5py.File) -> dict:
    if "fluid" not in f:
        return {}
    group = f["fluid"]
    fluid = {"model": str(group.attrs.get("model", ""))}
    if "shape" in group.attrs:  # a 3D grid: its grid fields
        for key in ("origin", "spacing", "shape"):
            fluid[key] = group.attrs[key][...]
        nz_ny_nx = tuple(int(n) for n in fluid["shape"][::-1])
        names = [name for name, series in group.items() if series["value"].shape[1:4] == nz_ny_nx]
    else:  # a column of layers (vans1d): its profiles
        names = list(group)
    for name in names:
        fluid["time"] = group[name]["time"][...]
        fluid[name] = (group[name]["value"][...], str(group[name]["value"].attrs.get("unit", "")))
    return fluid


def plot_run(run_dir: str | Path, out_dir: str | Path | None = None) -> list[Path]:
    """Write the PNG figures of a run directory (default: into RUN_DIR/plots); returns the paths."""
    run_dir = Path(run_dir)
    trajectory = run_dir / "trajectory.h5" if run_dir.is_dir() else run_dir
    if not trajectory.is_file():
        raise MissingInputError(f"{trajectory}: no trajectory to plot (is {run_dir} a run directory?)")
    plt = _pyplot()
    series, shear, fluid = _read(trajectory)
    out = Path(out_dir) if out_dir is not None else trajectory.parent / "plots"
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"{out}: cannot create the plot folder ({exc})") from None
    written = []
    labels = {"stress_zz": "sigma_zz", "stress_shear": f"tau = -sigma_z{shear}"}
    for figure, (ylabel, names) in SERIES.items():
        present = [n for n in names if n in series and series[n][1].ndim == 1 and series[n][1].size]
        if not present:
            continue
        if figure == "deformation":
            fig, axes = plt.subplots(
                len(present), 1, sharex=True, figsize=(7, 2.6 * len(present)), squeeze=False
            )
            for ax, name in zip(axes[:, 0], present, strict=True):
                t, v, unit = series[name]
                ax.plot(t, v)
                ax.set_ylabel(f"{name} [{unit or '-'}]")
            axes[-1, 0].set_xlabel("time [s]")
        else:
            fig, ax = plt.subplots(figsize=(7, 4))
            for name in present:
                t, v, _ = series[name]
                ax.plot(t, v, label=labels.get(name, name))
            ax.set_xlabel("time [s]")
            ax.set_ylabel(ylabel)
            ax.legend(fontsize="small")
        fig.suptitle(f"{run_dir.name}: {figure}")
        fig.tight_layout()
        written.append(_save(fig, out / f"{figure}.png", plt))
    if "layer_center" in series:
        written.append(_profiles(series, shear, run_dir.name, out, plt))
    for figure in (_structure, _strain, _pore_pressure, _bedload_profiles, _bedload_series, _fluid_slices):
        fig = figure(series, shear, fluid, plt)
        if fig is not None:
            name = figure.__name__.lstrip("_")
            fig.suptitle(f"{run_dir.name}: {name.replace('_', ' ')}")
            fig.tight_layout()
            written.append(_save(fig, out / f"{name}.png", plt))
    if not written:
        raise MissingInputError(
            f"{trajectory}: no observables to plot; list them in output.observables.quantities"
        )
    return written


def _profiles(series: dict, shear: str, title: str, out: Path, plt) -> Path:
    t, z, _ = series["layer_center"]
    panels = [
        ("packing_fraction_profile", "solid fraction [-]", lambda v: v),
        ("stress_profile", "sigma_zz [Pa]", lambda v: v[:, 2, 2]),
        (
            "stress_profile",
            f"tau = -sigma_z{shear} [Pa]",
            lambda v: -0.5 * (v[:, 2, "xyz".index(shear)] + v[:, "xyz".index(shear), 2]),
        ),
        ("velocity_profile", f"mean v_{shear} [m/s]", lambda v: v[:, "xyz".index(shear)]),
    ]
    panels = [p for p in panels if p[0] in series]
    fig, axes = plt.subplots(1, len(panels), sharey=True, figsize=(3.2 * len(panels), 4.5), squeeze=False)
    samples = t.size
    shown = sorted({samples - 1, *np.linspace(0, samples - 1, min(samples, 4)).astype(int).tolist()})
    for ax, (name, label, pick) in zip(axes[0], panels, strict=True):
        values = series[name][1]
        for k in shown:
            ax.plot(pick(values[k]), z[k], marker=".", label=f"t = {t[k]:.3g} s")
        ax.set_xlabel(label)
        ax.set_ylabel("height z [m]")
    axes[0, -1].legend(fontsize="small")
    fig.suptitle(f"{title}: profiles")
    fig.tight_layout()
    return _save(fig, out / "profiles.png", plt)


def _save(fig, path: Path, plt) -> Path:
    try:
        fig.savefig(path, dpi=110)
    except OSError as exc:
        raise OutputError(f"{path}: cannot write the figure ({exc})") from None
    finally:
        plt.close(fig)
    return path


def _structure(series: dict, shear: str, fluid: dict, plt):
    """Packing fractions and coordination numbers in time, each on its own axis."""
    panels = [(label, [n for n in names if n in series]) for label, names in STRUCTURE]
    panels = [(label, names) for label, names in panels if names]
    if not panels:
        return None
    fig, axes = plt.subplots(len(panels), 1, sharex=True, figsize=(7, 2.8 * len(panels)), squeeze=False)
    for ax, (label, names) in zip(axes[:, 0], panels, strict=True):
        for name in names:
            ax.plot(series[name][0], series[name][1], label=name.replace("_", " "))
        ax.set_ylabel(label)
        ax.legend(fontsize="small")
    axes[-1, 0].set_xlabel("time [s]")
    return fig


def _strain(series: dict, shear: str, fluid: dict, plt):
    """Stress ratio and dilation against strain, from the end of the first (preparation) stage,
    the stages shaded: shear strain where the top wall shears (direct shear), else the axial
    strain (H_0 - H)/H_0 of the sample height H."""
    needed = ("stage", "stress", "sample_height")
    if not all(n in series for n in needed):
        return None
    stage = series["stage"][1]
    keep = stage >= 1 if stage.max() >= 1 else np.ones(stage.size, dtype=bool)
    if keep.sum() < 2:
        return None
    sigma = series["stress"][1][keep]
    height = series["sample_height"][1][keep]
    h0 = height[0]
    a = "xyz".index(shear)
    gamma = series.get("shear_strain", (None, np.zeros(stage.size)))[1][keep]
    if np.ptp(gamma) > 0:  # the top wall shears: tau/sigma_n against the shear strain
        strain, strain_label = gamma - gamma[0], "shear strain gamma [-]"
        ratio = -0.5 * (sigma[:, 2, a] + sigma[:, a, 2]) / sigma[:, 2, 2]
        ratio_label = f"stress ratio tau/sigma_n = -sigma_z{shear}/sigma_zz [-]"
    else:  # compression: deviator over mean stress against the axial strain
        strain, strain_label = (h0 - height) / h0, "axial strain (H0 - H)/H0 [-]"
        p = np.trace(sigma, axis1=1, axis2=2) / 3.0
        ratio = (sigma[:, 2, 2] - 0.5 * (sigma[:, 0, 0] + sigma[:, 1, 1])) / p
        ratio_label = "stress ratio q/p [-]"
    volume = _wall_volume(series, keep)
    if volume is not None:
        dilation, dilation_label = (volume - volume[0]) / volume[0], "volumetric strain (V - V0)/V0 [-]"
    else:
        dilation, dilation_label = (height - h0) / h0, "dilation (H - H0)/H0 [-]"
    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(7, 6))
    axes[0].plot(strain, ratio)
    axes[0].set_ylabel(ratio_label)
    axes[1].plot(strain, dilation)
    axes[1].set_ylabel(dilation_label)
    axes[1].set_xlabel(strain_label)
    _shade_stages(axes, strain, stage[keep])
    return fig


def _wall_volume(series: dict, keep) -> np.ndarray | None:
    """Volume between the walls [m^3], where all six faces have one (a triaxial cell)."""
    if "wall_position" not in series or "wall_faces" not in series:
        return None
    faces = series["wall_faces"]
    if len(faces) != 6:
        return None
    position = series["wall_position"][1][keep]
    volume = np.ones(position.shape[0])
    for axis in "xyz":
        volume *= position[:, faces.index(f"{axis}+")] - position[:, faces.index(f"{axis}-")]
    return volume


def _shade_stages(axes, x, stage) -> None:
    """Alternate shading from the first sample of each stage to the first of the next (the
    samples run in time, stages one after the other), its index written at the top."""
    starts = [0, *(np.flatnonzero(np.diff(stage)) + 1).tolist()]
    for i, begin in enumerate(starts):
        end = starts[i + 1] if i + 1 < len(starts) else x.size - 1
        lo, hi = sorted((x[begin], x[end]))
        k = int(stage[begin])
        for ax in axes:
            ax.axvspan(lo, hi, color="0.85" if k % 2 else "0.93", zorder=0)
        axes[0].text(
            0.5 * (lo + hi),
            1.0,
            f"stage {k}",
            transform=axes[0].get_xaxis_transform(),
            ha="center",
            va="bottom",
            fontsize="small",
        )


def _pore_pressure(series: dict, shear: str, fluid: dict, plt):
    """Darcy: horizontal mean of the pore pressure against depth at a few times, and in time at
    the bottom, middle and top cells."""
    if fluid.get("model") != "darcy" or "pressure" not in fluid:
        return None
    pressure, unit = fluid["pressure"]
    mean = pressure.mean(axis=(2, 3))  # (frames, nz)
    z = fluid["origin"][2] + (np.arange(mean.shape[1]) + 0.5) * fluid["spacing"][2]
    depth = z.max() + 0.5 * fluid["spacing"][2] - z
    t = fluid["time"]
    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 4.5))
    for k in sorted({0, *np.linspace(0, t.size - 1, min(t.size, 5)).astype(int).tolist()}):
        left.plot(mean[k], depth, marker=".", label=f"t = {t[k]:.3g} s")
    left.invert_yaxis()
    left.set_xlabel(f"pore pressure [{unit or 'Pa'}]")
    left.set_ylabel("depth below the top of the grid [m]")
    left.legend(fontsize="small")
    for j in sorted({0, mean.shape[1] // 2, mean.shape[1] - 1}):
        right.plot(t, mean[:, j], label=f"depth {depth[j]:.3g} m")
    right.set_xlabel("time [s]")
    right.set_ylabel(f"pore pressure [{unit or 'Pa'}]")
    right.legend(fontsize="small")
    return fig


def _bedload_profiles(series: dict, shear: str, fluid: dict, plt):
    """1D VANS: fluid velocity, solid fraction and sediment flux density phi v_p against height,
    at a few frames."""
    names = ("layer_height", "fluid_velocity", "solid_fraction", "particle_velocity")
    if fluid.get("model") != "vans1d" or not all(n in fluid for n in names):
        return None
    t = fluid["time"]
    z, z_unit = fluid["layer_height"]
    phi = fluid["solid_fraction"][0]
    velocity, v_unit = fluid["particle_velocity"]
    panels = [
        (fluid["fluid_velocity"][0], f"fluid velocity [{fluid['fluid_velocity'][1]}]"),
        (phi, "solid fraction [-]"),
        (phi * velocity, f"sediment flux density phi v_p [{v_unit}]"),
    ]
    fig, axes = plt.subplots(1, 3, sharey=True, figsize=(11, 4.5))
    shown = sorted({t.size - 1, *np.linspace(0, t.size - 1, min(t.size, 4)).astype(int).tolist()})
    for ax, (values, label) in zip(axes, panels, strict=True):
        for k in shown:
            ax.plot(values[k], z[k], label=f"t = {t[k]:.3g} s")
        ax.set_xlabel(label)
        ax.set_ylabel(f"height [{z_unit}]")
    axes[-1].legend(fontsize="small")
    return fig


def _bedload_series(series: dict, shear: str, fluid: dict, plt):
    """1D VANS: Shields number and dimensionless sediment flux Q* in time."""
    if not ("shields_number" in series and "q_star" in series):
        return None
    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(7, 5.5))
    axes[0].plot(series["shields_number"][0], series["shields_number"][1])
    axes[0].set_ylabel("Shields number [-]")
    axes[1].plot(series["q_star"][0], series["q_star"][1])
    axes[1].set_ylabel("dimensionless flux Q* [-]")
    axes[1].set_xlabel("time [s]")
    return fig


def _fluid_slices(series: dict, shear: str, fluid: dict, plt):
    """Navier-Stokes: pressure and velocity magnitude (arrows: its x-z part) in the x-z plane
    through the middle of the box, last frame."""
    if fluid.get("model") != "navier-stokes" or "pressure" not in fluid or "velocity" not in fluid:
        return None
    (nx, ny, nz), origin, spacing = fluid["shape"], fluid["origin"], fluid["spacing"]
    j = int(ny) // 2
    pressure, p_unit = fluid["pressure"]
    velocity, v_unit = fluid["velocity"]
    extent = [origin[0], origin[0] + nx * spacing[0], origin[2], origin[2] + nz * spacing[2]]
    p = pressure[-1][:, j, :]  # (nz, nx)
    v = velocity[-1][:, j, :, :]  # (nz, nx, 3)
    speed = np.sqrt((v**2).sum(axis=-1))
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.8))
    for ax, field, label in (
        (axes[0], p, f"pressure [{p_unit}]"),
        (axes[1], speed, f"|velocity| [{v_unit}]"),
    ):
        image = ax.imshow(field, origin="lower", extent=extent, aspect="equal")
        fig.colorbar(image, ax=ax, label=label)
        ax.set_xlabel("x [m]")
        ax.set_ylabel("z [m]")
        ax.locator_params(axis="x", nbins=4)
    xc = origin[0] + (np.arange(nx) + 0.5) * spacing[0]
    zc = origin[2] + (np.arange(nz) + 0.5) * spacing[2]
    axes[1].quiver(xc, zc, v[..., 0], v[..., 2], color="white")
    axes[0].set_title(f"y = {origin[1] + (j + 0.5) * spacing[1]:.3g} m, t = {fluid['time'][-1]:.3g} s")
    return fig
