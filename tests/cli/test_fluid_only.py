"""Fluid-only scenes: a case with a [fluid] section and no particles (no [particles], or
count = 0) runs the fluid alone, for every fluid model, through the real CLI: the outputs read
back, the physics is that of the fluid alone (a column at rest stays at rest, a prescribed
pressure difference gives the linear Darcy profile, clear water down a slope the laminar
half-parabola), the DEM part is out of the step, and a resume continues bitwise. A dry scene
without particles is refused, as are the keys that need particles."""

from __future__ import annotations

import json
import math
import shutil
import subprocess
from pathlib import Path

import h5py
import numpy as np
import pytest
from cli_test_support import assert_clean_error, edit, sphere, sphere_inproc

from sphere_cli.config.load import parse_case
from sphere_cli.io.checkpoint import list_checkpoints, read_checkpoint
from sphere_cli.scene.builder import build_scene
from sphere_cli.verify import vans1d_exact as exact

RHO, G = 1000.0, 9.81

# A column of water at rest under gravity in a laterally periodic box, no-flow bottom, open top
# at 0 Pa. dt = "auto" is 0.9 x the viscous limit dx^2/(8 nu) of the 2.5 mm cells, 0.70 s: 4 steps.
NAVIER_STOKES = """\
title = "a column of water at rest"

[simulation]
duration = 3.0

[domain]
upper = [0.01, 0.01, 0.02]
periodic = [true, true, false]

[fluid]
model = "navier-stokes"
grid = { cells = [4, 4, 8] }

[output.frames]
every_steps = 1
"""

# Darcy flow up a 0.1 m column between 1000 Pa at the bottom and 0 Pa at the top; steady after
# a fraction of the first step (L^2 / D = L^2 beta phi mu / k = 4e-5 s against dt = 1 ms).
DARCY = """\
title = "seepage through a rigid column"

[simulation]
duration = 0.01
dt = 0.001

[domain]
upper = [0.01, 0.01, 0.1]

[particles]
count = 0

[fluid]
model = "darcy"
grid = { cells = [1, 1, 10] }
permeability = { model = "constant", value = 1.0e-10 }
bottom = { type = "pressure", pressure = 1000.0 }
top = { type = "pressure", pressure = 0.0 }

[output.frames]
every_steps = 5
"""

# Laminar clear water 1 cm deep down a slope (g_x = 0.098 m/s^2), nu = 1e-4 m^2/s, started
# from its steady profile; dt = "auto" is the default coupling interval, 1 ms.
VANS1D = """\
title = "clear water down a slope"

[simulation]
duration = 0.01

[domain]
upper = [0.01, 0.01, 0.01]
periodic = [true, true, false]
gravity = [0.098, 0.0, -9.81]

[fluid]
model = "vans1d"
viscosity = 1.0e-4
surface = 0.01
cells = 20
flow = { kind = "solved", mixing_length = "none", dt = 1.0e-3 }

[output.frames]
every_steps = 5
"""


def run(tmp_path, text: str, name: str = "case", *args):
    case = tmp_path / f"{name}.toml"
    case.write_text(text)
    out = tmp_path / name
    result = sphere_inproc("run", case, "-o", out, *args)
    assert_clean_error(result, 0)
    return out


def test_navier_stokes_column_stays_at_rest(tmp_path):
    """Gravity alone would bring the water to g t = 29 m/s in 3 s; the hydrostatic pressure holds
    it at rest to round-off (below 1e-9 m/s: the weight balanced to 1 part in 1e10), and the
    pressure stays hydrostatic, rho g (H - z) at the cell centres, to the solver's tolerance."""
    out = run(tmp_path, NAVIER_STOKES)
    with h5py.File(out / "trajectory.h5", "r") as f:
        assert list(f["particles/trajectory"]) == ["box"]  # no particle datasets at all
        assert list(f["particles/trajectory/box/edges/step"][...]) == [0, 1, 2, 3, 4]
        assert list(f["fluid/velocity/step"][...]) == [0, 1, 2, 3, 4]
        velocity = f["fluid/velocity/value"][...]
        pressure = f["fluid/pressure/value"][-1]  # (nz, ny, nx)
        assert float(f["fluid/velocity/time"][-1]) > 2.5
    assert np.abs(velocity).max() < 1e-9
    z = (np.arange(8) + 0.5) * 0.0025
    hydrostatic = RHO * G * (0.02 - z)
    assert np.allclose(pressure, hydrostatic[:, None, None], rtol=1e-9, atol=0.0)
    sidecar = (out / "trajectory.xmf").read_text()
    assert 'Grid Name="fluid"' in sidecar and 'Grid Name="particles"' not in sidecar
    ckpt = read_checkpoint(list_checkpoints(out / "checkpoints")[-1])
    assert sorted(ckpt.arrays) == ["fluid"] and ckpt.step == 4
    shown = sphere_inproc("inspect", out)
    assert_clean_error(shown, 0)
    assert "particles: 0" in shown.stdout and "model: navier-stokes" in shown.stdout


def test_darcy_pressure_difference_gives_the_linear_profile(tmp_path):
    """Steady Darcy flow through a uniform medium: p linear from 1000 Pa at z = 0 to 0 at
    z = 0.1 m (exact in the discrete equations, to the solver's tolerance), and a uniform Darcy
    velocity k dp/(mu L) / phi = 1e-3 / 0.9 m/s (phi: porosity_max, the open fluid clamped)."""
    out = run(tmp_path, DARCY)
    with h5py.File(out / "trajectory.h5", "r") as f:
        assert "position" not in f["particles/trajectory"]
        assert list(f["fluid/pressure/step"][...]) == [0, 5, 10]
        pressure = f["fluid/pressure/value"][-1][:, 0, 0]
        velocity = f["fluid/darcy_velocity/value"][-1][:, 0, 0]  # (nz, 3)
        assert "darcy_mean_pressure" in f["observables"]
    z = (np.arange(10) + 0.5) * 0.01
    assert np.allclose(pressure, 1000.0 * (1.0 - z / 0.1), rtol=1e-6, atol=1e-6)
    assert np.allclose(velocity[:, 2], 1.0e-3 / 0.9, rtol=1e-6)
    assert np.abs(velocity[:, :2]).max() == 0.0
    assert (out / "trajectory.xmf").is_file()


@pytest.mark.skipif(shutil.which("pvbatch") is None, reason="ParaView's pvbatch is not installed")
def test_paraview_shows_the_fluid_alone(tmp_path):
    """ParaView's XDMF 3 reader finds one block, the fluid cells, with the fields of the frame."""
    out = run(tmp_path, DARCY)
    probe = Path(__file__).parents[1] / "io" / "paraview_probe.py"
    command = [shutil.which("pvbatch"), str(probe), "Xdmf3ReaderS", str(out / "trajectory.xmf")]
    result = subprocess.run(command, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr
    seen = json.loads(result.stdout.strip().splitlines()[-1])
    assert seen["times"] == pytest.approx([0.0, 0.005, 0.01])
    [fluid] = seen["blocks"]
    assert fluid["cells"] == 10 and {"pressure", "darcy_velocity"} <= set(fluid["cell_arrays"])
    with h5py.File(out / "trajectory.h5", "r") as f:
        stored = f["fluid/pressure/value"][-1].reshape(-1)
    assert np.array_equal(np.ravel(fluid["cell_arrays"]["pressure"]), stored)


def test_vans1d_clear_water_profile(tmp_path):
    """Laminar free-surface flow: u = (g_x / nu) (h z - z^2/2), second order in the layer
    thickness (the wall's half layer makes the error 1/(4 n^2) of u_max for this parabola;
    asserted below 1/n^2), and the bed shear stress is the weight of the water along the slope,
    rho g_x h, exactly (the discrete momentum balance)."""
    out = run(tmp_path, VANS1D)
    with h5py.File(out / "trajectory.h5", "r") as f:
        assert sorted(f["fluid"]) == ["fluid_velocity", "layer_height"]  # no solid profiles
        z = f["fluid/layer_height/value"][-1]
        u = f["fluid/fluid_velocity/value"][-1]
        tau = f["observables/bed_shear_stress/value"][...]
        assert list(f["observables"]) == ["bed_shear_stress"]
    exact = 0.098 / 1.0e-4 * (0.01 * z - z**2 / 2.0)
    assert np.abs(u - exact).max() < exact.max() / 20**2
    assert np.allclose(tau, RHO * 0.098 * 0.01, rtol=1e-9)
    assert not (out / "trajectory.xmf").exists()  # nothing for ParaView: no particles, no 3D grid
    assert_clean_error(sphere_inproc("inspect", out / "trajectory.h5"), 0)


def test_the_dem_part_is_out_of_the_step():
    """No particle motion, neighbour search or contacts, and the fluid's forces on the particles
    are not called: the step is the fluid's own step and nothing else."""
    scene = build_scene(parse_case(NAVIER_STOKES))
    assert scene.motion is None and scene.neighbors is None and scene.contact is None
    step = scene.step
    assert step.kick_drift == step.prepare == step.forces == step.kick == step.finish_step == ()
    assert [module for module, _ in step.after_step] == [scene.fluid]
    assert list(step.stateful) == ["fluid"]


# Water between an open top at 0 Pa and a bottom whose pressure oscillates: it flows up and
# down the column. Gravity off, dt given: 40 steps, stopped after 17 and resumed.
OSCILLATING = """\
[simulation]
duration = 0.4
dt = 0.01

[domain]
upper = [0.01, 0.01, 0.02]
periodic = [true, true, false]
gravity = [0.0, 0.0, 0.0]

[fluid]
model = "navier-stokes"
grid = { cells = [4, 4, 8] }
bottom = { type = "pressure", pressure = 0.0, amplitude = 1.0, period = 0.2 }

[output]
frames = { every_steps = 5 }
"""


def test_fluid_only_resume_is_bitwise(tmp_path):
    case = tmp_path / "case.toml"
    case.write_text(OSCILLATING)
    assert_clean_error(sphere_inproc("run", case, "-o", tmp_path / "whole"), 0)
    assert_clean_error(sphere_inproc("run", case, "-o", tmp_path / "split", "--until", "0.17"), 0)
    assert_clean_error(sphere("resume", tmp_path / "split"), 0)  # a fresh process, as a batch job
    a, b = (read_checkpoint(list_checkpoints(tmp_path / d / "checkpoints")[-1]) for d in ("whole", "split"))
    assert a.step == b.step == 40 and sorted(a.arrays) == sorted(b.arrays) == ["fluid"]
    for name, value in a.arrays["fluid"].items():
        assert np.array_equal(value, b.arrays["fluid"][name]), name
    with (
        h5py.File(tmp_path / "whole" / "trajectory.h5", "r") as fw,
        h5py.File(tmp_path / "split" / "trajectory.h5", "r") as fs,
    ):
        assert np.array_equal(fw["fluid/velocity/step"][...], np.arange(0, 41, 5))
        # the split run has one frame more, at its stop (step 17)
        assert list(fs["fluid/velocity/step"][...]) == [0, 5, 10, 15, 17, 20, 25, 30, 35, 40]
        common = [0, 1, 2, 3, 5, 6, 7, 8, 9]
        for name in ("pressure", "velocity"):
            assert np.array_equal(fw[f"fluid/{name}/value"][...], fs[f"fluid/{name}/value"][common])
        # the fluid does move: up to 2 A / (rho H omega) = 3.2 mm/s, back to rest after each period
        assert np.abs(fw["fluid/velocity/value"][...]).max() > 1e-3
    assert 'Grid Name="fluid"' in (tmp_path / "split" / "trajectory.xmf").read_text()


def _dry(text: str) -> str:
    """The case without its [fluid] table (everything from [fluid] to the next table)."""
    start = text.index("[fluid]")
    end = text.index("\n[", start + 1)
    return text[:start] + text[end + 1 :]


@pytest.mark.parametrize(
    ("text", "fragments"),
    [
        (_dry(NAVIER_STOKES), ("particles: required key is missing", "unless it has a [fluid] section")),
        (_dry(DARCY), ("particles.count = 0", "needs a [fluid] section")),
        (edit(NAVIER_STOKES, "[fluid]", '[[walls]]\nface = "z-"\n\n[fluid]'), ("walls", "remove [[walls]]")),
        (
            edit(NAVIER_STOKES, "every_steps = 1\n", 'every_steps = 1\n\n[output]\nfields = ["velocity"]\n'),
            ("output.fields", "no per-particle fields"),
        ),
        (
            edit(
                NAVIER_STOKES,
                "[output.frames]",
                '[output.observables]\nquantities = ["energy"]\n\n[output.frames]',
            ),
            ("output.observables.quantities", "measure the particles"),
        ),
        (
            edit(NAVIER_STOKES, "grid = { cells = [4, 4, 8] }", "grid = {}"),
            ("fluid.grid", "cells or cell_size"),
        ),
        (
            edit(DARCY, 'permeability = { model = "constant", value = 1.0e-10 }\n', ""),
            ("fluid.permeability.coefficient", "required key is missing"),
        ),
    ],
    ids=["dry-no-particles", "dry-count-0", "walls", "fields", "quantities", "auto-grid", "kozeny-carman"],
)
def test_refused_without_particles(tmp_path, text, fragments):
    """Refused by `validate` already (exit 65), naming the key and what is expected."""
    case = tmp_path / "case.toml"
    case.write_text(text)
    assert_clean_error(sphere_inproc("validate", case), 65, *fragments)


def test_auto_dt_without_any_limit_is_refused(tmp_path):
    """Darcy's implicit step has no limit and no particles are there to couple: "auto" has
    nothing to take, and the run asks for dt (or a coupling interval) before writing anything."""
    case = tmp_path / "case.toml"
    case.write_text(edit(DARCY, "dt = 0.001", 'dt = "auto"'))
    result = sphere_inproc("run", case, "-o", tmp_path / "run")
    assert_clean_error(result, 65, "simulation.dt", "give dt in seconds")
    assert not (tmp_path / "run").exists()
    case.write_text(edit(DARCY, "dt = 0.001", 'dt = "auto"') + "\n[fluid.coupling]\ninterval = 0.002\n")
    out = tmp_path / "interval"
    assert_clean_error(sphere_inproc("run", case, "-o", out), 0)
    assert read_checkpoint(list_checkpoints(out / "checkpoints")[-1]).dt == 0.002  # one step a fluid step


def test_auto_dt_longer_than_the_run_is_the_run():
    """dt = "auto" of a fluid alone is 0.9 x its limit (0.70 s for the column at rest); a run of
    0.1 s takes one step of 0.1 s, ending at its duration instead of overshooting it."""
    scene = build_scene(parse_case(edit(NAVIER_STOKES, "duration = 3.0", "duration = 0.1")))
    assert scene.state.clock.dt == 0.1


def test_vans1d_over_an_imposed_solid_fraction_is_the_exact_li_sawamoto_flow(tmp_path):
    """[fluid.solid_fraction] imposes the smooth bed of vans1d_exact.py (c = 0.25 (1 - tanh((z -
    30 mm)/10 mm)), 401 points) on a clear-water run down a 0.05 rad slope, 0.1 m deep on 100
    layers stretched 1e4x, Li & Sawamoto's mixing length: the steady profile the run starts from
    is the exact one of that form within 0.3 % (the verification case c1-vans1d-li-sawamoto
    measures 0.15 % on the same layers), and the imposed profile is written with the frames."""
    z = np.linspace(0.0, 0.1, 401)
    points = ", ".join(repr(float(v)) for v in z)
    values = ", ".join(repr(float(v)) for v in exact.bed_solid(z))
    g = exact.G
    text = f"""
[simulation]
duration = 0.01
[domain]
upper = [0.01, 0.01, 0.1]
periodic = [true, true, false]
gravity = [{g * math.sin(exact.SLOPE)!r}, 0.0, {-g * math.cos(exact.SLOPE)!r}]
[fluid]
model = "vans1d"
viscosity = {exact.NU!r}
surface = 0.1
cells = 100
stretching = 1.0e4
packed_solid_fraction = {exact.PACKED!r}
flow = {{ kind = "solved", mixing_length = "li-sawamoto", dt = 0.01, initial = "steady" }}
solid_fraction = {{ z = [{points}], value = [{values}] }}
"""
    out = run(tmp_path, text)
    with h5py.File(out / "trajectory.h5", "r") as f:
        centres = f["fluid/layer_height/value"][0]
        u = f["fluid/fluid_velocity/value"][0]
        solid = f["fluid/solid_fraction/value"][0]
    reference = exact.free_surface_velocity("li-sawamoto", centres)
    assert np.abs(u - reference).max() < 0.003 * reference.max()
    assert np.allclose(solid, exact.bed_solid(centres), atol=1e-4)
