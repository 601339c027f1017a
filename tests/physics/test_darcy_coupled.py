"""The Darcy fluid coupled to particles (physics/fluid/darcy.py): a bed under an upward seepage
gradient, bitwise resume, and scenes without it left alone.

Critical gradient of this model: the fluid force on a particle of volume V is -V grad p plus
the buoyancy -rho_f V g (the original sphere's Darcy coupling, kernels/fluid/darcy.py), so a bed
whose particles see on average an upward excess-pressure gradient -dp/dz = (rho_s - rho_f)|g|
carries its whole buoyant weight: i_c = (rho_s - rho_f)|g|. The bed here is a simple cubic stack
of 200 touching spheres (d = 1 mm) on a floor, at rest; the gradient the particles see is the
volume-weighted mean of grad p interpolated at their centres, after one fluid step (the
diffusion time H^2/D ~ 1e-9 s is far below the step, so that is the steady state).
"""

from __future__ import annotations

import math
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from sphere_cli import api
from sphere_cli.config.load import parse_case
from sphere_cli.io.checkpoint import list_checkpoints, read_checkpoint
from sphere_cli.kernels.fluid.darcy import add_pressure_forces
from sphere_cli.scene.builder import build_scene
from sphere_cli.simulation import advance

RHO_S, RHO_F, G = 2650.0, 1000.0, 9.81
CRITICAL = (RHO_S - RHO_F) * G  # [Pa/m]
D = 1.0e-3

BED = """
[simulation]
duration = {duration}
dt = 4.0e-6
stability = "contact"
[domain]
upper = [0.005, 0.005, 0.025]
periodic = [true, true, false]
[particles]
count = 200
density = 2650.0
radius = {{ distribution = "fixed", value = 0.0005 }}
placement = {{ method = "lattice", spacing = 1.0, region_upper = [0.005, 0.005, 0.0085] }}
[contact]
model = "linear"
normal_stiffness = 1.0e3
restitution = 0.2
friction = 0.5
[[walls]]
face = "z-"
[fluid]
model = "darcy"
density = 1000.0
grid = {{ cells = [2, 2, 10] }}
bottom = {{ pressure = {pressure} }}
top = {{ pressure = 0.0 }}
coupling = {{ steps = {update_every} }}
[output]
frames = {{ every_steps = 100 }}
checkpoints = {{ every_steps = {checkpoint_every} }}
"""


def bed_case(
    pressure: float, duration: float = 0.01, update_every: int = 1, checkpoint_every: int = 1000
) -> str:
    return BED.format(
        pressure=pressure, duration=duration, update_every=update_every, checkpoint_every=checkpoint_every
    )


def mean_upward_gradient(scene) -> float:
    """Volume-weighted mean over the particles of -dp/dz at their centres [Pa/m]."""
    p, fluid = scene.state.particles, scene.fluid
    grid = fluid.grid()
    force = np.zeros_like(p.force)
    add_pressure_forces(
        p.pos, p.radius, fluid.pore.state.gradient, grid.origin, grid.spacing,
        fluid.pore.periodic, 0.0, np.zeros(3), force,
    )  # fmt: skip
    return float(force[:, 2].sum() / (4.0 / 3.0 * np.pi * (p.radius**3).sum()))


@pytest.fixture(scope="module")
def pressure_per_gradient() -> float:
    """Bottom pressure that gives the particles a mean upward gradient of 1 Pa/m (the steady
    problem is linear in the boundary pressure)."""
    reference = 100.0
    scene = build_scene(parse_case(bed_case(reference)))
    advance(scene, 1)
    return reference / mean_upward_gradient(scene)


@pytest.mark.parametrize("ratio", [0.8, 2.2])
def test_bed_under_upward_gradient(ratio, pressure_per_gradient):
    """0.8 i_c: no particle moves by 1 % of a diameter in 0.012 s (3000 steps). 2.2 i_c: the
    bed lifts; the net upward acceleration is 1.2 (rho_s - rho_f)/rho_s |g| = 7.3 m/s^2, a rise
    of 0.53 mm in 0.012 s if nothing held it back; the mean rise must pass half of that."""
    scene = build_scene(parse_case(bed_case(ratio * CRITICAL * pressure_per_gradient)))
    start = scene.state.particles.pos.copy()
    advance(scene, 1)
    assert mean_upward_gradient(scene) == pytest.approx(ratio * CRITICAL, rel=1e-3)
    advance(scene, 2999)
    shift = scene.state.particles.pos - start
    rise = 0.5 * 1.2 * (RHO_S - RHO_F) / RHO_S * G * 0.012**2
    if ratio < 1:
        assert np.max(np.abs(shift)) < 0.01 * D
    else:
        assert shift[:, 2].mean() > 0.5 * rise
        assert shift[:, 2].min() > 0.0


def test_coupling_is_stable_at_its_time_step_limit():
    """The coupling is explicit (forces from the pressure of the last fluid step): a compacting
    bed pressurises its pore water, which pushes back one step later, like a drag of relaxation
    time rho_s k / mu. The model's limit is 0.2 of that time (physics/fluid/darcy.py). A loose lattice
    settling in a medium of constant k chosen so that dt = 4e-6 s is exactly that limit stays
    finite and slow for 1000 steps and compacts. (Measured with this scene: stable at a fluid
    step of 0.3 rho_s k / mu, blown up within 100 steps at 0.5.)"""
    dt = 4.0e-6
    k = 1.0e-3 * dt / (0.2 * RHO_S)
    law = f'permeability = {{ model = "constant", value = {k!r} }}'
    text = bed_case(0.0).replace('model = "darcy"', f'model = "darcy"\n{law}')
    text = text.replace("spacing = 1.0, region_upper = [0.005, 0.005, 0.0085]", "spacing = 1.2, jitter = 0.8")
    scene = build_scene(parse_case(text))
    assert scene.dt_limit == pytest.approx(dt, rel=1e-12)
    p = scene.state.particles
    start = p.pos[:, 2].mean()
    advance(scene, 1000)
    assert np.all(np.isfinite(scene.fluid.pore.state.pressure))
    assert np.abs(p.vel).max() < 0.1  # a free fall over these 4 ms reaches 0.04 m/s
    assert p.pos[:, 2].mean() < start


def test_resume_is_bitwise_identical(tmp_path: Path):
    """A run stopped at a step between two fluid steps (fluid.coupling.steps = 3) and resumed ends in
    exactly the state of an uninterrupted one: particles, pressure, porosities and gradient."""
    case = tmp_path / "bed.toml"
    case.write_text(bed_case(3.0 * CRITICAL * 0.01, duration=200 * 4e-6, update_every=3, checkpoint_every=50))
    api.run(case, tmp_path / "whole")
    api.run(case, tmp_path / "split", until=100 * 4e-6)
    api.resume(tmp_path / "split")
    a = read_checkpoint(list_checkpoints(tmp_path / "whole" / "checkpoints")[-1])
    b = read_checkpoint(list_checkpoints(tmp_path / "split" / "checkpoints")[-1])
    assert a.step == b.step == 200
    assert set(a.arrays) == set(b.arrays) and "fluid" in a.arrays
    for group in a.arrays:
        for name, value in a.arrays[group].items():
            assert np.array_equal(value, b.arrays[group][name]), f"{group}/{name} differs"
    assert np.any(a.arrays["fluid"]["pressure"] != 0.0)


CONFIGS = Path(__file__).resolve().parents[2] / "configs"


def test_scenes_without_darcy_do_not_load_it(tmp_path: Path):
    """A dry scene, and scenes of the other fluid models (configs/bedload.toml, vans1d;
    configs/fluid-settling.toml, navier-stokes), build and step without importing the Darcy
    physics or kernels (the case schema, config/fluid_darcy.py, is part of every case's
    validation). One fresh interpreter builds the three in turn."""
    dry = tmp_path / "dry.toml"
    dry.write_text(bed_case(0.0).split("[fluid]")[0] + "[output]\nframes = { every_steps = 100 }\n")
    cases = [str(dry), str(CONFIGS / "bedload.toml"), str(CONFIGS / "fluid-settling.toml")]
    script = textwrap.dedent(
        f"""
        import sys
        from sphere_cli.scene.builder import build_scene
        from sphere_cli.config.load import load_case
        from sphere_cli.simulation import advance
        for path, model in zip({cases!r}, (None, "vans1d", "navier-stokes")):
            scene = build_scene(load_case(path))
            advance(scene, 3)
            assert (scene.fluid.model if scene.fluid is not None else None) == model, path
            print(sorted(m for m in sys.modules if m.split(".")[-1] in ("darcy", "pore_pressure")))
        """
    )
    out = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["[]"] * 3


OEDOMETER = """
[simulation]
duration = 1.0
dt = 3.0e-6
stability = "contact"
[domain]
upper = [0.004, 0.004, 0.008]
periodic = [true, true, false]
gravity = [0.0, 0.0, 0.0]
[particles]
count = 128
density = 2650.0
radius = {{ distribution = "fixed", value = 0.0005 }}
placement = {{ method = "lattice", spacing = 1.0 }}
[contact]
model = "linear"
normal_stiffness = 1.0e3
restitution = 0.2
friction = 0.5
[[walls]]
face = "z-"
[[walls]]
face = "z+"
mode = "stress"
stress = {stress}
{fluid}
"""


def test_consolidation_under_a_stress_controlled_wall():
    """A bed (8 touching layers of 1 mm spheres, no gravity) loaded at t = 0 by a top wall held
    at sigma = 2 kPa, drained at the top, impermeable at the base, k = 7.2e-12 m^2. Dry, the
    bed settles by 9 contacts x (sigma d^2 / k_n) = 1.8e-5 m at once (m_v = 1.125e-6 1/Pa).
    Saturated, the water first carries the load (Skempton B ~ 1: the pore pressure at the base
    rises to about sigma), then drains, and the settlement follows; after 12 ms (1.2 H^2/c_v,
    c_v = k/(mu m_v)) it has reached the dry settlement and the excess pressure is gone.
    Measured: base pressure 1.16 sigma at 1 ms, settlement there 0.55 of the final one (dry:
    1.08, the wall overshooting).
    Not Terzaghi to the percent: the pressure here decays about 2.8 times faster than the
    series' slowest mode (4 cells over the bed, porosity sampled by the lens method on a
    lattice aligned with the grid: suspected, not investigated); the test checks the
    coupling's behaviour, not U(T)."""
    sigma, final = 2000.0, 9 * 2000.0 * 1e-6 / 1e3
    fluid = """[fluid]
model = "darcy"
grid = { cells = [2, 2, 4] }
permeability = { model = "constant", value = 7.2e-12 }
top = { pressure = 0.0 }
bottom = { type = "no-flow" }"""
    settlements = {}
    for name, table in (("dry", ""), ("wet", fluid)):
        scene = build_scene(parse_case(OEDOMETER.format(stress=sigma, fluid=table)))
        walls = scene.state.walls
        top = list(walls.faces).index("z+")
        start = walls.coord[top]
        advance(scene, 333)  # 1 ms
        settlements[name] = start - walls.coord[top]
        if name == "wet":
            base = scene.fluid.pore.state.pressure[:, :, 0].mean()
            assert 0.8 * sigma < base < 1.5 * sigma
            advance(scene, 4000 - 333)
            assert start - walls.coord[top] == pytest.approx(final, rel=0.01)
            assert np.max(np.abs(scene.fluid.pore.state.pressure)) < 0.01 * sigma
    assert settlements["wet"] < 0.7 * settlements["dry"]  # the dry wall is already there (overshooting)


FIXED_LIGHT = """
[simulation]
duration = 0.001
dt = "auto"
[domain]
upper = [0.004, 0.004, 0.01]
periodic = [true, true, false]
[[materials]]
name = "sand"
density = 2650.0
[[materials]]
name = "cork"
density = 240.0
[particles]
material = ["sand", "cork"]
placement = { method = "file", path = "bed.csv" }
[contact]
model = "linear"
normal_stiffness = 1.0e3
[[walls]]
face = "z-"
[fluid]
model = "darcy"
density = 1000.0
grid = { cells = [2, 2, 5] }
permeability = { model = "constant", value = 1.0e-9 }
"""


@pytest.mark.parametrize("sand_fixed", [0, 1])
def test_the_coupling_limit_counts_only_particles_that_move(tmp_path, sand_fixed):
    """Fixed cork spheres (240 kg/m^3) under free sand (2650): the explicit coupling's limit
    0.2 rho_s k/mu takes rho_s of the sand, the lightest particles that move (the fixed ones are
    pushed but do not answer), not the cork's, which would make dt 11 times smaller. With the
    sand fixed as well nothing answers, and the coupling sets no limit."""
    rows = ["x,y,z,r,material,fixed"]
    rows += [f"{x},{y},0.0005,0.0005,cork,1" for x in (0.001, 0.003) for y in (0.001, 0.003)]
    rows += [f"{x},{y},0.0025,0.0005,sand,{sand_fixed}" for x in (0.001, 0.003) for y in (0.001, 0.003)]
    (tmp_path / "bed.csv").write_text("\n".join(rows) + "\n")
    scene = build_scene(parse_case(FIXED_LIGHT, tmp_path / "case.toml"))
    limit, reason = scene.fluid.fluid_step_limit()
    if sand_fixed:
        assert limit == math.inf and "no particle moves" in reason
    else:
        assert limit == pytest.approx(0.2 * 2650.0 * 1.0e-9 / 1.0e-3, rel=1e-9)
        assert "2650 kg/m^3" in reason
