"""The GPU step (physics/device_steps.py, kernels/cuda_dem.py) against the CPU's, run under
Numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1, set in tests/conftest.py) so that it is tested
on machines without a GPU; on a GPU machine, NUMBA_ENABLE_CUDASIM=0 runs the same tests on the
device.

The scene: 40 spheres of two materials in a periodic box, thrown at random so that they collide,
slide, roll and cross the periodic faces, for enough steps that the list is rebuilt on the
device. The simulator runs the kernels' arithmetic in double precision without fused
multiply-adds, as the CPU does: the positions, velocities, forces and springs must be bitwise the
CPU's. On a GPU the compiler fuses multiplies and adds (one rounding instead of two), and
the contacts amplify such differences step after step (a chaotic system): the tolerance there is
relative 1e-9 after these tens of steps, far above 1e-16 per operation and far below any
physical change.
"""

from __future__ import annotations

import json
import math
import os
import re
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from numba import config as numba_config
from test_contact_blocks import HERTZ_MATERIALS

from sphere_cli.api import _with_simulation
from sphere_cli.config.load import parse_case
from sphere_cli.errors import CaseError
from sphere_cli.physics import device_steps
from sphere_cli.physics.compiled_steps import CompiledSteps
from sphere_cli.physics.neighbors import spring_rows
from sphere_cli.scene.builder import build_scene
from sphere_cli.simulation import advance

BOX = 0.008
COUNT = 40
SIMULATED = bool(numba_config.ENABLE_CUDASIM)
# bitwise under the simulator; round-off amplified by the contacts on a GPU (module docstring)
RTOL = 0.0 if SIMULATED else 1e-9


def _placement(path, seed: int = 3, lift: float = 0.0) -> None:
    rng = np.random.default_rng(seed)
    side = 4
    grid = (np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), -1).reshape(-1, 3) + 0.5) / side
    pos = (grid[:COUNT] + rng.uniform(-0.01, 0.01, (COUNT, 3))) * BOX + [0.0, 0.0, lift]
    radius = rng.uniform(0.00095, 0.00104, COUNT)
    # towards the centre, and at random: they keep colliding
    vel = 40.0 * (0.5 * BOX - pos) + rng.normal(0.0, 0.1, (COUNT, 3))
    rows = ["x,y,z,r,vx,vy,vz"] + [
        ",".join(repr(float(v)) for v in (*p, r, *u)) for p, r, u in zip(pos, radius, vel, strict=True)
    ]
    path.write_text("\n".join(rows) + "\n")


def _case(path, device: str, hertz: bool = True, extra: str = "") -> str:
    contact = (
        'model = "hertz-mindlin"\nrestitution = 0.5\nfriction = 0.4\nrolling_friction = 0.05'
        if hertz
        else 'model = "linear"\nnormal_stiffness = 2000.0\nrestitution = 0.5\nfriction = 0.4'
    )
    materials = (
        HERTZ_MATERIALS
        if hertz
        else """
        [[materials]]
        name = "a"
        density = 2500.0
        [[materials]]
        name = "b"
        density = 7800.0
        normal_stiffness = 5000.0
        """
    )
    return (
        textwrap.dedent(
            f"""
            [simulation]
            duration = 1.0
            dt = 1.0e-5
            stability = "contact"
            device = "{device}"
            [domain]
            upper = [{BOX}, {BOX}, {BOX}]
            periodic = [true, true, true]
            gravity = [0.0, 0.0, -9.81]
            [particles]
            material = {{ a = 0.5, b = 0.5 }}
            overlap_tolerance = 0.5
            placement = {{ method = "file", path = "{path}" }}
            [contact]
            """
        )
        + contact
        + textwrap.dedent(materials)
        + extra
    )


def _pairs(scene) -> dict:
    """Each listed pair's spring, keyed by (i, j): the list's layout may differ, its pairs not
    (none without friction)."""
    nl = scene.state.neighbors
    if not nl.hist.shape[0]:
        return {}
    rows = spring_rows(nl)
    return {
        (i, int(nl.nbr[i, k])): rows[i, k]
        for i in range(nl.nbr.shape[0])
        for k in range(min(int(nl.nbr_count[i]), nl.nbr.shape[1]))
        if rows[i, k].any()
    }


FLOOR_AND_LID = '\n[[walls]]\nface = "z-"\nmaterial = "b"\n[[walls]]\nface = "z+"\n'
# a rough floor sliding along x at a set velocity, a lid keeping a stress with a sine on it and
# driven along y by a shear stress: every mode of physics/walls.py, and spheres glued to a wall
MOVING_WALLS = """
[[walls]]
face = "z-"
material = "b"
rough = {}
mode = "velocity"
velocity = 0.0
shear_axis = "x"
shear_velocity = 0.05
[[walls]]
face = "z+"
mode = "stress"
stress = 500.0
stress_amplitude = 200.0
frequency = 300.0
shear_axis = "y"
shear_stress = 50.0
"""


def _scenes(tmp_path, seed: int = 3, hertz: bool = True, walls: str = "", friction: float = 0.4):
    """The scene on the GPU and on the CPU; with walls (FLOOR_AND_LID or MOVING_WALLS), a floor
    and a lid instead of the periodic z axis (the spheres pressed against both at first)."""
    path = tmp_path / "spheres.csv"
    # the spheres glued to the rough floor lie on its plane: the others a radius higher
    lift = 0.001 if "rough" in walls else 0.0
    _placement(path, seed, lift)
    texts = [
        _case(path, device, hertz, walls).replace("friction = 0.4", f"friction = {friction}")
        for device in ("cuda", "cpu")
    ]
    if walls:
        texts = [text.replace("[true, true, true]", "[true, true, false]") for text in texts]
        texts = [text.replace(f"{BOX}]", f"{BOX + lift}]") for text in texts]
    return tuple(build_scene(parse_case(text)) for text in texts)


def _compare(gpu, cpu) -> None:
    for name in ("pos", "vel", "angvel", "force", "torque"):
        a, b = getattr(gpu.state.particles, name), getattr(cpu.state.particles, name)
        np.testing.assert_allclose(a, b, rtol=RTOL, atol=RTOL * np.abs(b).max(), err_msg=name)
    a, b = _pairs(gpu), _pairs(cpu)
    scale = max((np.abs(v).max() for v in b.values()), default=0.0)  # none without friction
    if SIMULATED:
        assert a.keys() == b.keys()
    # on a GPU a contact touching or parting within round-off may exist on one side only: its
    # spring is then of the order of that round-off's travel, tiny against the others
    for key in a.keys() | b.keys():
        one, other = a.get(key, np.zeros(3)), b.get(key, np.zeros(3))
        np.testing.assert_allclose(one, other, rtol=RTOL, atol=max(RTOL, 1e-6 * (not SIMULATED)) * scale)


@pytest.mark.parametrize(
    "hertz, walls",
    [(True, ""), (False, ""), (True, FLOOR_AND_LID), (False, MOVING_WALLS)],
    ids=["hertz-rolling", "linear", "walls", "moving-walls"],
)
def test_gpu_steps_are_the_cpu_steps(tmp_path, hertz, walls):
    gpu, cpu = _scenes(tmp_path, hertz=hertz, walls=walls)
    assert type(gpu.step.compiled).__name__ == "DeviceSteps"
    builds = cpu.state.neighbors.builds
    contacts = []
    for steps in (1, 29, 30):  # a single step, then runs that end between list builds
        advance(gpu, steps)
        advance(cpu, steps)
        _compare(gpu, cpu)
        contacts.append(len(_pairs(cpu)))
    # the scene did what the test needs: the list rebuilt on the device, contacts with springs
    # all along; rebuilt at the CPU's steps (results do not show a list rebuilt too often)
    assert gpu.state.neighbors.builds - builds >= 2
    if SIMULATED:  # (on a GPU a displacement within round-off of the skin may part them)
        assert gpu.state.neighbors.builds == cpu.state.neighbors.builds
    assert min(contacts) >= 5, contacts
    if walls:  # wall springs too, each bitwise (the CPU's layout: (N,W,3))
        # (the moving walls': the lid's; the rough floor's spheres touch the others instead)
        assert np.count_nonzero(cpu.state.walls.hist.any(axis=2)) >= (3 if walls == FLOOR_AND_LID else 1)
        np.testing.assert_allclose(gpu.state.walls.hist, cpu.state.walls.hist, rtol=RTOL, atol=RTOL * 1e-3)
    if walls == MOVING_WALLS:  # the walls moved on the device as on the CPU
        a, b = gpu.state.walls, cpu.state.walls
        assert b.attached.size > 0 and np.abs(b.shift).min(axis=1).max() == 0.0  # each a direction
        assert np.abs(b.shift[0, 0]) > 1e-6 and np.abs(b.shift[1, 1:]).min() > 0.0
        assert (np.abs(b.force[:, 2]) > 0.0).all()  # the glued spheres and the lid pushed
        for name in ("coord", "vel", "acc", "shift", "force", "area"):
            one, other = getattr(a, name), getattr(b, name)
            np.testing.assert_allclose(one, other, rtol=RTOL, atol=RTOL * np.abs(other).max(), err_msg=name)
    assert gpu.state.clock.step == cpu.state.clock.step == 60


# a Navier-Stokes fluid over the floor on a 2 x 2 x 3 grid, open at the top, solved every 5 steps:
# the drag of each particle (with its self-induced velocity subtracted, the default) and its
# exact kick on the device; the pressure solved there too, to 1e-13 (DARCY below says why)
NAVIER_STOKES = """
[[walls]]
face = "z-"
material = "b"
[fluid]
model = "navier-stokes"
density = 1000.0
viscosity = 1.0e-3
grid = { cells = [2, 2, 3] }
coupling = { steps = 5 }
bottom = { type = "no-flow" }
top = { type = "pressure", pressure = 0.0 }
solver = { tolerance = 1e-13 }
"""

# Darcy pore pressure on a 2 x 2 x 3 grid, pulsed from below, solved every 5 steps (on the GPU:
# its fused multiply-adds round otherwise than the CPU, and a solve stopped at 1e-13 keeps the
# difference at round-off, within RTOL)
DARCY = """
[[walls]]
face = "z-"
material = "b"
[fluid]
model = "darcy"
grid = { cells = [2, 2, 3] }
coupling = { steps = 5 }
bottom = { type = "pressure", pressure = 80.0, amplitude = 60.0, period = 0.0002 }
top = { type = "pressure", pressure = 0.0 }
solver = { tolerance = 1e-13 }
"""

# a frictionless first stage that ends on its kinetic-energy test (tested every 10 steps from
# step 20), then the lid approaching the spheres, keeping a stress and sliding, with friction
STAGES = """
[[stages]]
name = "settle"
duration = 0.01
friction = 0.0
stop_when = { kinetic_energy_below = 1.0e9, min_time = 0.0002 }
check_every = 10
[[stages]]
name = "shear"
duration = 0.01
[[stages.walls]]
face = "z+"
mode = "stress"
stress = 500.0
approach = true
shear_axis = "x"
shear_velocity = 0.05
"""


@pytest.mark.parametrize(
    "grid", ["", "fixed", "following"], ids=["dry", "navier-stokes", "navier-stokes-grid-following"]
)
def test_stages_run_on_the_gpu_as_on_the_cpu(tmp_path, grid):
    """Stages on the GPU: the state comes back for each test of a stage's end, and goes up again
    when the next stage has set the walls' modes, the friction and moved the lid (approach). In
    a Navier-Stokes fluid, whose steps (every 5 steps) fall on those tests: on a grid that keeps
    its cells (the porosity and the exchange made on the device) and on one following the lid."""
    fluid = ""
    if grid:
        fluid = NAVIER_STOKES[NAVIER_STOKES.index("[fluid]") :]
        if grid == "following":
            fluid = fluid.replace("cells = [2, 2, 3] }", "cells = [2, 2, 3], follow_top_wall = true }")
    gpu, cpu = _scenes(tmp_path, walls=FLOOR_AND_LID + STAGES + fluid)
    assert type(gpu.step.compiled).__name__ == "DeviceSteps"
    # a test that does not end the stage brings back only what it reads: the state stays stale
    advance(gpu, 10, sync=False)
    advance(cpu, 10)
    assert gpu.step.compiled.host_stale
    np.testing.assert_allclose(gpu.state.particles.vel, cpu.state.particles.vel, rtol=RTOL)
    advance(gpu, 5)
    advance(cpu, 5)
    for steps in (25, 20) if not grid else (25,):  # the first stage ends inside the first call
        ended = [advance(gpu, steps), advance(cpu, steps)]
        assert ended[0] == ended[1]
        _compare(gpu, cpu)
    assert gpu.stages.index == cpu.stages.index == 1 and cpu.stages.start_step == 20
    a, b = gpu.state.walls, cpu.state.walls
    assert b.shift[1, 0] > 0.0 and b.shift[1, 2] != 0.0  # sheared, and moved by the approach
    for name in ("coord", "vel", "shift", "force"):
        one, other = getattr(a, name), getattr(b, name)
        np.testing.assert_allclose(one, other, rtol=RTOL, atol=RTOL * np.abs(other).max(), err_msg=name)


@pytest.mark.parametrize(
    "scene, launch",
    [("stages-navier-stokes", (2, 3)), ("moving-walls", (2, 24))],
    ids=["6-threads-navier-stokes", "48-threads-moving-walls"],
)
def test_the_steps_do_not_depend_on_the_launch(tmp_path, monkeypatch, scene, launch):
    """Every kernel strides over its particles or cells (kernels/cuda_dem.py): launches of 2
    blocks of 3 threads (each taking 6 or 7 of the 40 particles and 2 of the 12 fluid cells:
    the neighbour search, the contacts, the stages' walls, the porosity, the drag and its
    kick) and of 2 blocks of 24 (8 threads without a particle) step as the CPU does. On a GPU,
    blocks of that many threads, a thread an item."""
    if SIMULATED:
        monkeypatch.setattr(device_steps, "SIMULATOR_LAUNCH", launch)
    else:
        monkeypatch.setattr(device_steps, "THREADS", launch[1])
    if scene == "moving-walls":
        gpu, cpu = _scenes(tmp_path, hertz=False, walls=MOVING_WALLS)
        runs = (1, 29, 30)
    else:
        gpu, cpu = _scenes(
            tmp_path, walls=FLOOR_AND_LID + STAGES + NAVIER_STOKES[NAVIER_STOKES.index("[fluid]") :]
        )
        runs = (15, 25, 20)
    builds = cpu.state.neighbors.builds
    for steps in runs:
        advance(gpu, steps)
        advance(cpu, steps)
        _compare(gpu, cpu)
    assert gpu.state.neighbors.builds - builds >= 2
    np.testing.assert_allclose(gpu.state.walls.force, cpu.state.walls.force, rtol=RTOL)
    if scene != "moving-walls":
        assert gpu.stages.index == cpu.stages.index == 1
        for a, b in ((gpu.fluid.drag.f_drag, cpu.fluid.drag.f_drag), (gpu.fluid.fs.v, cpu.fluid.fs.v)):
            assert np.abs(b).max() > 0.0  # the fluid did act
            np.testing.assert_allclose(a, b, rtol=RTOL, atol=RTOL * np.abs(b).max())


def test_the_device_sums_the_forces_on_the_walls_as_the_cpu_does():
    """The particles' forces on the walls (most of them zero, over 16 orders of magnitude, so the
    order of a float sum would show in its bits) and the glued spheres', summed on the device by
    integer atomics (push_sums, then wall_motion_kick): bitwise the CPU's wall_totals, and the
    sums' words cleared for the next step."""
    from numba import cuda

    from sphere_cli.kernels import cuda_dem
    from sphere_cli.kernels.exact_sum import WORDS
    from sphere_cli.kernels.walls import C_MASS, NC, wall_totals

    rng = np.random.default_rng(2)
    n = 3000
    pforce = rng.normal(0.0, 1.0, (n, 3, 3)) * 10.0 ** rng.integers(-8, 9, (n, 3, 3))
    pforce[rng.random(n) < 0.8] = 0.0
    record = np.array([1, 0, 1], dtype=np.uint8)
    attached, attached_wall = rng.choice(n, 20, replace=False), rng.integers(0, 3, 20)
    total, mass = rng.normal(0.0, 1.0, (n, 3)), rng.random(n)
    body_acc, fluid_force = np.array([0.0, 0.0, -9.81]), rng.normal(0.0, 1.0, (3, 3))
    expected = np.zeros((3, 3))
    sums = np.zeros((3, 3, WORDS), dtype=np.int64)
    wall_totals(pforce, record, sums, attached, attached_wall, total, mass, body_acc, fluid_force, expected)

    on_device = cuda.to_device(np.zeros_like(sums))
    marked, force = cuda.to_device(record), cuda.to_device(np.zeros((3, 3)))
    cuda_dem.push_sums[-(-n // 128), 128](cuda.to_device(pforce), n, marked, on_device)
    # the walls fixed (mode 0) and at rest: only their forces matter here
    control = np.zeros((3, NC))
    control[:, C_MASS] = 1.0
    axis, sign = np.array([0, 1, 2]), np.ones(3)
    walls = [cuda.to_device(a) for a in (axis, sign, np.zeros(3), np.zeros(3), np.ones(3), np.zeros(3))]
    cuda_dem.wall_motion_kick[1, 1](
        on_device, marked, cuda.to_device(attached), cuda.to_device(attached_wall), cuda.to_device(total),
        cuda.to_device(mass), cuda.to_device(body_acc), cuda.to_device(fluid_force), force, *walls,
        cuda.to_device(np.zeros((3, 2), dtype=np.int64)), cuda.to_device(control),
        cuda.to_device(np.zeros((3, 3))), cuda.to_device(np.zeros((3, 3))), 0.0, 1e-6,
    )  # fmt: skip
    assert force.copy_to_host().tobytes() == expected.tobytes()
    assert not on_device.copy_to_host().any()
    assert np.array_equal(expected[1], fluid_force[1])  # not recorded: the fluid's alone
    for w in (0, 2):  # the exact sum, rounded, plus the fluid's force: within two roundings
        glued = attached[attached_wall == w]
        for b in range(3):
            terms = [*-pforce[:, w, b], *(total[glued, b] - mass[glued] * body_acc[b])]
            pushed = math.fsum(terms)  # correctly rounded
            exact = pushed + fluid_force[w, b]
            assert abs(expected[w, b] - exact) <= math.ulp(pushed) + math.ulp(exact)


def test_rows_and_cells_that_overflow_grow_on_the_device(tmp_path, monkeypatch):
    """Cells of one slot, and spare rows of one slot for the next build: the builds overflow,
    the device grows the arrays and builds again, and nothing is dropped (still the CPU's
    result)."""
    from sphere_cli.physics import device_steps

    monkeypatch.setattr(device_steps, "CELL_SLOTS", 1)
    gpu, cpu = _scenes(tmp_path, seed=11)
    advance(gpu, 1)
    advance(cpu, 1)
    device = gpu.step.compiled
    width = device.rows.nbr.shape[1]
    device.spare = device._allocate(COUNT, 1)
    builds = gpu.state.neighbors.builds
    advance(gpu, 60)
    advance(cpu, 60)
    _compare(gpu, cpu)  # every pair kept: the narrow rows grew
    assert gpu.state.neighbors.builds > builds
    assert device.cell_members.shape[1] > 1
    assert device.rows.nbr.shape[1] >= width


def test_changes_to_the_host_arrays_between_calls_reach_the_gpu(tmp_path):
    """A script or notebook that changes the state between calls of advance (a sphere pushed,
    the friction changed) sees the change in the GPU's steps, as on the CPU."""
    from sphere_cli.kernels.laws import MU

    gpu, cpu = _scenes(tmp_path, seed=7)
    for scene in (gpu, cpu):
        advance(scene, 20)
        scene.state.particles.vel[7] += [0.3, -0.2, 0.1]
        scene.contact.table[..., MU] = 0.1
        advance(scene, 20)
    _compare(gpu, cpu)


def test_a_gpu_checkpoint_continues_on_the_cpu(tmp_path):
    """The host's list after a GPU call is a valid CPU list: continuing on the CPU from it gives
    the CPU's own result (the springs carried in the CPU's layout)."""
    gpu, cpu = _scenes(tmp_path, seed=5)
    advance(gpu, 40)
    advance(cpu, 40)
    gpu.step.compiled = CompiledSteps.of(gpu.step)  # the GPU scene now steps on the CPU
    advance(gpu, 40)
    advance(cpu, 40)
    _compare(gpu, cpu)


def test_the_gpu_checks_stability_in_place_and_reports_as_the_cpu(tmp_path):
    """The stability check runs on the device without bringing the state back; a particle gone
    bad brings it back and stops the run with the CPU's message."""
    from sphere_cli.errors import NumericalError
    from sphere_cli.simulation import check_stable, hand_over

    gpu, cpu = _scenes(tmp_path)
    advance(gpu, 3, sync=False)
    advance(cpu, 3)
    check_stable(gpu)
    assert gpu.step.compiled.host_stale  # checked on the device: nothing came back
    hand_over(gpu)  # the host is changed below: taken up by the next steps
    messages = []
    for scene in (gpu, cpu):
        scene.state.particles.vel[7] = [0.0, 300.0, 0.0]  # 3 mm a step: beyond half a radius
        advance(scene, 1, sync=False)
        with pytest.raises(NumericalError) as caught:
            check_stable(scene)
        messages.append(str(caught.value))
    assert "particle 7" in messages[0] and "more than half its radius" in messages[0]
    # the same words; the same numbers, to the round-off of the GPU's fused multiply-adds
    words, numbers = zip(*(_words_and_numbers(m) for m in messages), strict=True)
    assert words[0] == words[1]
    np.testing.assert_allclose(numbers[0], numbers[1], rtol=RTOL)


def _words_and_numbers(message: str) -> tuple[str, list[float]]:
    number = r"[-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?"
    return re.sub(number, "#", message), [float(x) for x in re.findall(number, message)]


def test_what_the_gpu_does_not_run_is_refused_by_name():
    """A fluid without particles (the GPU steps particles): refused at load where the case says
    device = "cuda" (config/consistency.py, so `sphere validate` too), and at the build where
    `sphere run --device cuda` asks for it."""
    alone = textwrap.dedent(
        """
        [simulation]
        duration = 0.01
        dt = 0.001
        [domain]
        upper = [0.01, 0.01, 0.02]
        [fluid]
        model = "darcy"
        grid = { cells = [1, 1, 8] }
        permeability = { model = "constant", value = 1e-10 }
        """
    )
    with pytest.raises(CaseError, match=r'simulation.device = "cuda": the GPU steps particles'):
        parse_case(alone.replace("dt = 0.001", 'dt = 0.001\ndevice = "cuda"'))
    with pytest.raises(CaseError, match=r'simulation.device = "cuda".*also has: no particles'):
        build_scene(_with_simulation(parse_case(alone), device="cuda"))  # as `run --device cuda`


BUDGET = '\n[output.observables]\nquantities = ["energy_budget"]\n'


@pytest.mark.parametrize(
    "hertz, walls, friction",
    [(True, "", 0.4), (False, MOVING_WALLS, 0.4), (False, FLOOR_AND_LID, 0.0)],
    ids=["hertz-rolling", "moving-walls", "frictionless"],
)
def test_the_energy_budget_is_booked_on_the_gpu_as_on_the_cpu(tmp_path, hertz, walls, friction):
    """Each particle's share of the budget, booked on the device from its full rows (the
    partners below it left out), the springs and wall springs of the last step and the
    half-step velocities kept before the contacts: the CPU's, and so its observables (without
    friction, no springs at all)."""
    gpu, cpu = _scenes(tmp_path, hertz=hertz, walls=walls + BUDGET, friction=friction)
    assert type(gpu.step.compiled).__name__ == "DeviceSteps"
    for steps in (1, 29):
        advance(gpu, steps)
        advance(cpu, steps)
        _compare(gpu, cpu)
        a, b = gpu.budget.booked, cpu.budget.booked
        np.testing.assert_allclose(a, b, rtol=RTOL, atol=RTOL * np.abs(b).max())
    terms = cpu.budget.booked.any(axis=0)  # every term that can be is booked
    expected = [True, walls == MOVING_WALLS, True, friction > 0.0, hertz]
    assert list(terms) == expected, terms
    one, other = gpu.budget.observables(gpu.state), cpu.budget.observables(cpu.state)
    # on a GPU the residual and the energy change are differences of terms that differ by the
    # FMA round-off: compared against the largest term
    scale = max(abs(value) for value, _ in other.values())
    for name, (value, _) in other.items():
        assert math.isclose(one[name][0], value, rel_tol=RTOL, abs_tol=RTOL * scale), name


def test_no_gpu_is_a_case_error_naming_the_key(tmp_path, monkeypatch):
    from numba import cuda

    monkeypatch.setattr(cuda, "is_available", lambda: False)
    path = tmp_path / "spheres.csv"
    _placement(path)
    with pytest.raises(CaseError, match=r'simulation.device = "cuda": no GPU can be used here'):
        build_scene(parse_case(_case(path, "cuda")))


def test_every_kernel_compiles_for_a_gpu():
    """NVIDIA's compiler (numba-cuda's NVVM, the CUDA extra: make test-cuda) compiles every
    kernel for an H200 (tests/unit/cuda_ptx.py); a kernel of cuda_dem.py it does not list fails."""
    pytest.importorskip("numba_cuda", reason="the CUDA extra is not installed (make test-cuda)")
    import sphere_cli.kernels.cuda_dem as kernels

    helper = Path(__file__).with_name("cuda_ptx.py")
    # the project first, then whatever the environment already has on the path
    path = os.pathsep.join(filter(None, (str(Path(__file__).parents[2]), os.environ.get("PYTHONPATH"))))
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "0", "PYTHONPATH": path}
    done = subprocess.run([sys.executable, str(helper)], env=env, capture_output=True, text=True, timeout=900)
    assert done.returncode == 0, done.stderr[-3000:]
    compiled = {line.split()[0] for line in done.stdout.splitlines()}
    from sphere_cli.kernels.fluid import cuda_darcy, cuda_drag, cuda_porosity, cuda_profile_forces

    launched = {
        name
        for module in (kernels, cuda_profile_forces, cuda_darcy, cuda_drag, cuda_porosity)
        for name, value in vars(module).items()
        if not name.startswith("_")
        and hasattr(value, "py_func")
        and hasattr(value, "__getitem__")
        # not a device function, compiled where a kernel calls it (the simulator's kernels keep
        # the flag as _device)
        and not getattr(value, "targetoptions", {}).get("device", getattr(value, "_device", False))
    }
    assert launched and launched <= compiled, launched - compiled


def _final(run_dir: Path) -> dict:
    import h5py

    with h5py.File(run_dir / "trajectory.h5", "r") as f:
        frames = f["particles/trajectory"]
        final = {name: frames[name]["value"][-1] for name in ("position", "velocity", "force")}
        # measured on the host from the list as the GPU left it
        for name in ("contacts", "elastic_energy"):
            final[name] = f["observables"][name]["value"][-1]
        if "fluid" in f:  # the grid's fields
            final.update({name: field["value"][-1] for name, field in f["fluid"].items() if "value" in field})
        return final


@pytest.mark.parametrize("fluid", ["", NAVIER_STOKES, DARCY], ids=["dry", "navier-stokes", "darcy"])
def test_a_gpu_run_resumes_on_the_cpu_as_a_cpu_run(tmp_path, fluid):
    """sphere run --device cuda, sphere resume (still on the GPU), then sphere resume --device
    cpu from its checkpoint: the trajectory ends where a run on the CPU alone ends (bitwise
    under the simulator), so the checkpoint written from the GPU's state holds the whole state,
    springs included, and, in a Navier-Stokes fluid, the drag's arrays that stay on the device
    (its impulses, the drag of the next half kick, the self-induced velocity, the exchange's
    prediction); in a Darcy fluid, its pore pressure stepped on the device from the porosity
    measured there, restored on the host and taken up again by the device."""
    from sphere_cli import api

    path = tmp_path / "spheres.csv"
    _placement(path, seed=9)
    case = tmp_path / "case.toml"
    text = _case(path, "cpu", extra=fluid).replace("duration = 1.0", "duration = 0.0008")
    if fluid:
        text = text.replace("[true, true, true]", "[true, true, false]")
    case.write_text(
        text + "\n[output.frames]\nevery_time = 0.0004\n[output.checkpoints]\nevery_time = 0.0004\n"
    )
    api.run(case, tmp_path / "gpu", device="cuda", until=0.0004)
    api.resume(tmp_path / "gpu", until=0.0006)  # on the device it ran on, without --device
    api.resume(tmp_path / "gpu", device="cpu")
    api.run(case, tmp_path / "cpu")
    gpu, cpu = _final(tmp_path / "gpu"), _final(tmp_path / "cpu")
    assert cpu["contacts"] > 0
    for name in gpu:
        np.testing.assert_allclose(gpu[name], cpu[name], rtol=RTOL, atol=RTOL * np.abs(cpu[name]).max())
    log = (tmp_path / "gpu" / "run.log").read_text()
    assert log.count("steps on the GPU") == 2
    # where a fluid's parts run, for the batch log's reader
    own_step = "its own step every 5 steps: the grid's kernels and its pressure solve on the GPU"
    assert log.count(own_step) == (2 if fluid else 0)


def test_without_a_gpu_the_command_exits_65_naming_the_key(tmp_path):
    """The real CUDA target (no simulator) on a machine without a GPU: exit 65, the key named,
    no traceback, no run directory left behind."""
    path = tmp_path / "spheres.csv"
    _placement(path)
    case = tmp_path / "case.toml"
    case.write_text(_case(path, "cpu"))
    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "0"}
    probe = "from numba import cuda; print(cuda.is_available())"
    has_gpu = subprocess.run([sys.executable, "-c", probe], env=env, capture_output=True, text=True)
    if has_gpu.stdout.strip() == "True":
        pytest.skip("this machine has a GPU")
    sphere = Path(sys.executable).with_name("sphere")
    done = subprocess.run(
        [str(sphere), "run", str(case), "-o", str(tmp_path / "run"), "--device", "cuda", "-q"],
        env=env,
        capture_output=True,
        text=True,
    )
    assert done.returncode == 65, done.stderr
    assert 'simulation.device = "cuda": no GPU can be used here' in done.stderr
    assert "Traceback" not in done.stderr
    assert not (tmp_path / "run").exists()


def test_the_gpu_benchmark_reports_rate_memory_and_kernel_shares(tmp_path):
    """sphere bench gpu on a tiny loose bed, with a moving lid and in water (Navier-Stokes and
    Darcy; its figures mean nothing under the simulator; the test is that a session with a GPU can
    run it at once)."""
    from typer.testing import CliRunner

    from sphere_cli.cli import app

    result = CliRunner().invoke(
        app,
        [
            "bench",
            "gpu",
            "--sizes",
            "40",
            "--steps",
            "3",
            "--repeats",
            "1",
            "--states",
            "loose",
            "--walls",
            "fixed,moving",
            "--fluids",
            "none,navier-stokes,darcy",
            "-o",
            str(tmp_path),
        ],
    )
    assert result.exit_code == 0, result.output
    row, moving, in_water, in_pores = json.loads((tmp_path / "bench-gpu.json").read_text())["rows"]
    assert row["n"] == 40 and row["to_host_seconds"] > 0
    assert row["particle_steps_per_second"] > row["particle_steps_per_second_with_output"] > 0
    assert 200 < row["device_bytes_per_particle"] < 5000
    assert set(row["kernel_shares"]) == {"kick_drift", "pair_forces", "wall_forces", "kick"}
    assert abs(sum(row["kernel_shares"].values()) - 1.0) < 1e-9
    # the lid keeping a stress: the walls' own kernels and their sums are timed too
    assert (row["walls"], moving["walls"]) == ("fixed", "moving")
    walls_own = {"wall_motion_drift", "push_sums", "wall_motion_kick"}
    assert set(moving["kernel_shares"]) == {*row["kernel_shares"], *walls_own}
    # in water: the drag and its kick every step (the self-induced velocity's sums by cell), the
    # porosity and the momentum exchange before the fluid step of the third step
    assert (in_water["walls"], in_water["fluid"]) == ("fixed", "navier-stokes")
    drag = {"drag_forces", "count_in_cells", "cell_starts", "fill_cells", "cell_coefficients", "drag_kick"}
    coupling = {"bin_in_fluid_cells", "sort_cells", "sample_cells", "exchange"}
    host = {"fluid step"}  # the fluid's own step, timed beside the kernels
    assert set(in_water["kernel_shares"]) == ({*row["kernel_shares"], *drag, *coupling, *host} - {"kick"})
    # in a Darcy fluid: its force every step, the porosity and mean velocity before the fluid step
    assert (in_pores["walls"], in_pores["fluid"]) == ("fixed", "darcy")
    measured = {"bin_in_fluid_cells", "cell_starts", "fill_cells", "sort_cells", "sample_cells"}
    assert set(in_pores["kernel_shares"]) == {*row["kernel_shares"], "pressure_forces", *measured, *host}
