"""The Darcy fluid coupled to particles (physics/fluid/darcy.py): a bed under an upward seepage
gradient, walls the pore pressure pushes or not, bitwise resume, and scenes without it left
alone. Consolidation under a wall, drained (Terzaghi) and undrained (Skempton's B), are
verification cases (sphere_cli/verify/coupled_cases.py, d5-darcy-*), which
tests/verify/test_verify_quick.py runs.

Critical gradient (Terzaghi): the fluid pushes the grains with the seepage force -grad p per
unit volume of the mixture, -V grad p / (1 - phi) on a particle of volume V (kernels/fluid/darcy.py),
so a bed lifts when the excess-pressure drop across it carries its buoyant weight per unit
area, N V (rho_s - rho_f) |g| / A, whatever its porosity: the classical critical gradient
(1 - phi)(rho_s - rho_f)|g|. The bed here is a simple cubic stack of 200 touching spheres
(d = 1 mm) on a floor, at rest; the upward force is that of the pressure after one fluid step
(the diffusion time H^2/D ~ 1e-9 s is far below the step, so that is the steady state).
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
from sphere_cli.verify.coupled_cases import HEIGHT, oedometer

RHO_S, RHO_F, G = 2650.0, 1000.0, 9.81
D = 1.0e-3
AREA = 0.005 * 0.005  # [m^2] of the bed's box
BUOYANT_WEIGHT = 200 * math.pi / 6 * D**3 * (RHO_S - RHO_F) * G  # [N]

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


def bed_at_rest_case(model: str, top: float, nz: int, wall_speed: float | None = None) -> str:
    """Four layers of the bed above (100 spheres) at rest on a closed floor under water up to
    `top` [m], fluid `model` on 2 x 2 x nz cells; with wall_speed [m/s], a drained top wall
    moving at it (into the box) that the grid follows."""
    text = bed_case(0.0)
    follows = ", follow_top_wall = true" if wall_speed is not None else ""
    grid = f"grid = {{ cells = [2, 2, {nz}]{follows} }}"
    edits = [
        ("bottom = { pressure = 0.0 }", 'bottom = { type = "no-flow" }'),
        ("count = 200", "count = 100"),
        ("0.005, 0.0085]", "0.005, 0.0042]"),
        ("upper = [0.005, 0.005, 0.025]", f"upper = [0.005, 0.005, {top}]"),
        ('model = "darcy"', f'model = "{model}"'),
        ("grid = { cells = [2, 2, 10] }", grid),
    ]
    if wall_speed is not None:
        wall = f'[[walls]]\nface = "z+"\nmode = "velocity"\nvelocity = {wall_speed}\n'
        edits.append(("[fluid]", wall + "[fluid]"))
    for old, new in edits:
        assert text.count(old) == 1, old
        text = text.replace(old, new)
    return text


def upward_force(scene) -> float:
    """Total upward seepage force of the fluid on the particles, without the buoyancy [N]."""
    p, fluid = scene.state.particles, scene.fluid
    grid, s = fluid.grid(), fluid.pore.state
    force = np.zeros_like(p.force)
    add_pressure_forces(
        p.pos, p.radius, s.gradient, s.porosity_used, np.uint8(1), grid.origin, grid.spacing,
        fluid.pore.periodic, 0.0, np.zeros(3), force,
    )  # fmt: skip
    return float(force[:, 2].sum())


@pytest.fixture(scope="module")
def critical_pressure() -> float:
    """Bottom excess pressure whose seepage force carries the bed's buoyant weight (the steady
    problem is linear in the boundary pressure)."""
    reference = 100.0
    scene = build_scene(parse_case(bed_case(reference)))
    advance(scene, 1)
    return reference * BUOYANT_WEIGHT / upward_force(scene)


def test_the_bed_carries_the_whole_pressure_drop(critical_pressure):
    """The seepage force on the bed is the pressure drop across it times its area: the critical
    bottom pressure is the buoyant weight per unit area, 67.8 Pa, within 5 % (measured: 4 %
    above it; the bed's surface lies inside a cell 2.5 d high, where the gradient and porosity
    are interpolated across it, and 1 % of the drop is spent in the clear fluid above)."""
    assert critical_pressure == pytest.approx(BUOYANT_WEIGHT / AREA, rel=0.05)


@pytest.mark.parametrize("ratio", [0.8, 2.2])
def test_bed_under_upward_gradient(ratio, critical_pressure):
    """0.8 of the critical pressure: no particle moves by 1 % of a diameter in 0.012 s (3000
    steps). 2.2 times it: the bed lifts; the net upward acceleration is 1.2 (rho_s - rho_f)/rho_s
    |g| = 7.3 m/s^2, a rise of 0.53 mm in 0.012 s if nothing held it back; the mean rise must
    pass half of that."""
    scene = build_scene(parse_case(bed_case(ratio * critical_pressure)))
    start = scene.state.particles.pos.copy()
    advance(scene, 1)
    assert upward_force(scene) == pytest.approx(ratio * BUOYANT_WEIGHT, rel=1e-3)
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
    time rho_s k (1 - phi) / mu. The model's limit is 0.2 of that time at the porosity where
    it is shortest, porosity_max = 0.9 for a constant k (physics/fluid/darcy.py). A loose
    lattice settling in a medium of constant k chosen so that dt = 4e-6 s is exactly that limit
    stays finite and slow for 1000 steps and compacts. (Measured with this scene: stable at a
    fluid step of 1.5 times the relaxation time at 0.9, blown up at 2.)"""
    dt = 4.0e-6
    k = 1.0e-3 * dt / (0.2 * RHO_S * (1.0 - 0.9))
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
    case.write_text(
        bed_case(3.0 * BUOYANT_WEIGHT / AREA, duration=200 * 4e-6, update_every=3, checkpoint_every=50)
    )
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


def test_a_permeable_wall_moving_through_the_water_above_a_bed_does_not_lift_it():
    """Four layers of the bed of the tests above (100 spheres) at rest on a closed floor, a
    permeable (drained) top wall 21 mm above them moving down at 0.2 m/s through the water, the
    grid (2 x 2 x 4 cells) following it. The water crosses the wall, so nothing should push the
    bed: its grains stay where they settle with the wall at rest (within 1 um). The skeleton's
    divergence was made to integrate to the grid's change of volume, as under an impermeable
    wall: a compaction of the bed, whose drainage through it took +54 Pa of pore pressure at its
    base against its buoyant weight of 34 Pa per area, and lifted the top layer by 0.135 mm in
    0.02 s. Then the porosity rate of the cells moving with the grid, advected with the grains'
    velocity less the grid's, left the lens estimate's error in cells that slid past grains at
    rest: -42 Pa at the base (a suction). The rate is now taken in a frame moving with the
    grains (kernels/fluid/porosity.py rate_in_grains_frame), here fixed in space: no excess
    pore pressure (allowed 0.01 Pa, against the bed's buoyant weight of 34 Pa per area)."""
    tops = []
    for speed in (0.0, 0.2):
        scene = build_scene(parse_case(bed_at_rest_case("darcy", 0.025, 4, speed)))
        advance(scene, 5000)
        assert scene.state.walls.coord[1] > 0.0209  # still 17 mm above the bed
        assert np.abs(scene.fluid.pore.state.pressure).max() < 0.01
        tops.append(float(scene.state.particles.pos[:, 2].max()))
    assert abs(tops[1] - tops[0]) < 1e-6


def test_a_permeable_wall_takes_no_pore_pressure():
    """Only an impermeable wall is pushed by the pore pressure under it: a permeable one has
    the same pressure on both faces and carries the effective stress alone."""
    permeable, top = oedometer("{ pressure = 500.0 }")
    sealed, _ = oedometer('{ type = "no-flow" }')
    for scene in (permeable, sealed):
        scene.fluid.pore.state.pressure[...] = 500.0
        advance(scene, 1)
    assert np.all(permeable.state.walls.fluid_force == 0.0)
    area = 0.004 * 0.004
    assert sealed.state.walls.fluid_force[top, 2] == pytest.approx(500.0 * area, rel=0.01)


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
    0.2 rho_s k (1 - porosity_max)/mu takes rho_s of the sand, the lightest particles that move
    (the fixed ones are pushed but do not answer), not the cork's, which would make dt 11 times
    smaller. With the sand fixed as well nothing answers, and the coupling sets no limit."""
    rows = ["x,y,z,r,material,fixed"]
    rows += [f"{x},{y},0.0005,0.0005,cork,1" for x in (0.001, 0.003) for y in (0.001, 0.003)]
    rows += [f"{x},{y},0.0025,0.0005,sand,{sand_fixed}" for x in (0.001, 0.003) for y in (0.001, 0.003)]
    (tmp_path / "bed.csv").write_text("\n".join(rows) + "\n")
    scene = build_scene(parse_case(FIXED_LIGHT, tmp_path / "case.toml"))
    limit, reason = scene.fluid.fluid_step_limit()
    if sand_fixed:
        assert limit == math.inf and "no particle moves" in reason
    else:
        assert limit == pytest.approx(0.2 * 2650.0 * 1.0e-9 * (1.0 - 0.9) / 1.0e-3, rel=1e-9)
        assert "2650 kg/m^3" in reason


def test_a_wall_pushed_by_a_stiffer_fluid_than_its_time_step_counted_is_warned_once(caplog):
    """The wall's dt limit counts the undrained fluid at the build's height and phi = 0.26; when
    the live stiffness passes what was counted (here made so by lowering the counted value), one
    warning names both, and the run goes on."""
    scene, _ = oedometer('{ type = "no-flow" }')
    counted = scene.fluid.assumed_wall_stiffness
    assert counted == pytest.approx(0.004 * 0.004 / (HEIGHT * 4.5e-10 * 0.26), rel=1e-9)
    scene.fluid.assumed_wall_stiffness = 1.0
    with caplog.at_level("WARNING", logger="sphere.fluid.darcy"):
        advance(scene, 3)
    warned = [r for r in caplog.records if "stiff" in r.getMessage()]
    assert len(warned) == 1 and "1 N/m the time step was chosen for" in warned[0].getMessage()


def test_a_scene_run_in_memory_steps_its_grid_on_the_process_threads():
    """api.run_in_memory (tests, notebooks) keeps the process's thread count for every part,
    as it says; `sphere run` sizes the grid's step by its cells (tests/unit/test_shared_cores.py)."""
    from sphere_cli.bench.darcy import case_text

    assert api.run_in_memory(case_text(4, 27, 1e-8), 0).fluid.step_threads is None


@pytest.mark.parametrize("porosity_min", [None, 0.5])
def test_the_clamp_is_warned_of_below_porosity_min_and_logged_above_porosity_max(caplog, porosity_min):
    """Cells above porosity_max are taken at it by design (the open water above the bed, 24 of
    the grid's 40 cells of 2.5 mm; the 4 sparse cells of the bed's surface, 7.5-10 mm): one
    line of run.log at INFO, no warning (every run with water above its bed warned at its first
    step). A porosity_min above the simple cubic bed's 0.476 clamps its cells from below: one
    warning, naming how many and the lowest porosity."""
    case = bed_case(0.0)
    if porosity_min is not None:
        case = case.replace('model = "darcy"\n', f'model = "darcy"\nporosity_min = {porosity_min}\n')
    scene = build_scene(parse_case(case))
    with caplog.at_level("INFO", logger="sphere.fluid.darcy"):
        advance(scene, 3)
    warned = [r.getMessage() for r in caplog.records if r.levelname == "WARNING"]
    logged = [
        r.getMessage() for r in caplog.records if r.levelname == "INFO" and "porosity_max" in r.getMessage()
    ]
    above = "above fluid.porosity_max = 0.9 taken as 0.9 in 28 of 40 fluid cells at step 1"
    assert logged == [f"Darcy: porosity {above} (24 of them open water)"]
    if porosity_min is None:
        assert warned == []
    else:  # the 12 cells of the 3 layers inside the bed, lens estimate 0.472
        assert len(warned) == 1, warned
        assert "below fluid.porosity_min = 0.5 in 12 of 40 fluid cells at step 1 (lowest 0.472)" in warned[0]
