"""`sphere plot RUN_DIR`: PNG figures of a run's observables (matplotlib, the `plot` extra).

Time series, one figure per family, of whatever the run recorded:
  stress.png       pressure, sigma_zz and the shear traction tau = -sigma_zx (or -sigma_zy) [Pa]
  friction.png     effective friction tau/sigma_n [-]
  deformation.png  dilation [-] and sample height [m]
  energy.png       kinetic, elastic, potential energy; with the budget, the work of gravity and
                   walls, the dissipated energies and the balance residual [J]
  structure.png    packing fractions and coordination numbers [-]
Profiles against height at the last sample (and a few earlier ones):
  profiles.png     solid fraction, sigma_zz, shear stress and mean velocity per layer
"""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from .errors import MissingDependency, MissingInputError, OutputError

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
    "structure": (
        "[-]",
        ["packing_fraction", "packing_fraction_interior", "coordination", "coordination_no_rattlers"],
    ),
}


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


def _read(trajectory: Path) -> tuple[dict, str]:
    """name -> (time (S,), value (S, ...), unit), and the shear axis letter."""
    try:
        with h5py.File(trajectory, "r") as f:
            series = {}
            for name, group in f["observables"].items():
                unit = group["value"].attrs.get("unit", "")
                series[name] = (group["time"][...], group["value"][...], str(unit))
            import json

            resolved = json.loads(f["parameters"].attrs["resolved_case"])
    except (OSError, KeyError) as exc:
        raise OutputError(f"{trajectory}: not a readable sphere trajectory ({exc})") from None
    shear = resolved.get("output", {}).get("observables", {}).get("shear_direction", "x")
    if "stress" in series:
        t, sigma, unit = series["stress"]
        a = "xyz".index(shear)
        series["stress_zz"] = (t, sigma[:, 2, 2], unit)
        series["stress_shear"] = (t, -0.5 * (sigma[:, 2, a] + sigma[:, a, 2]), unit)
    return series, shear


def plot_run(run_dir: str | Path, out_dir: str | Path | None = None) -> list[Path]:
    """Write the PNG figures of a run directory (default: into RUN_DIR/plots); returns the paths."""
    run_dir = Path(run_dir)
    trajectory = run_dir / "trajectory.h5" if run_dir.is_dir() else run_dir
    if not trajectory.is_file():
        raise MissingInputError(f"{trajectory}: no trajectory to plot (is {run_dir} a run directory?)")
    plt = _pyplot()
    series, shear = _read(trajectory)
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
    axes[0, 0].set_ylabel("height z [m]")
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
