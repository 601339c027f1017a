"""The fluids' action on the particles on the GPU (physics/device_steps.py with a fluid's
GpuSteps, kernels/fluid/cuda_*.py) against the CPU's, under Numba's CUDA simulator (bitwise) or
on a GPU (NUMBA_ENABLE_CUDASIM=0; the tolerance of tests/unit/test_cuda_dem.py, whose scene of 40
colliding spheres, now over a floor in a fluid, these tests share)."""

from __future__ import annotations

import copy
from pathlib import Path

import numpy as np
import pytest
from test_cuda_dem import DARCY, NAVIER_STOKES, RTOL, SIMULATED, _compare, _scenes

from sphere_cli.physics.fluid.poisson import PoissonResult
from sphere_cli.physics.fluid.pore_pressure import STEP_OUTPUTS
from sphere_cli.scene.builder import build_scene
from sphere_cli.simulation import advance


@pytest.mark.parametrize("cells", [7, 100], ids=["heap-sorted", "insertion-sorted"])
def test_the_device_sorts_particles_by_fluid_cell_and_sums_in_particle_order(cells):
    """The particles sorted by fluid cell on the device (atomic counts and fill, then each cell
    sorted) are the CPU's stable counting sort (kernels/neighbors.py counting_sort), whatever
    order the fill leaves; so the sums of the drag coefficients per cell (the self-induced
    velocity's screening) are bitwise the CPU's in particle order (kernels/fluid/drag.py
    cell_coefficients): here with each cell's particles handed over reversed, and coefficients
    over sixteen decades, so that a sum in that order differs."""
    from numba import cuda

    from sphere_cli.kernels.fluid import cuda_drag, cuda_porosity
    from sphere_cli.kernels.fluid.drag import cell_coefficients
    from sphere_cli.kernels.neighbors import counting_sort

    rng = np.random.default_rng(4)
    n = 300  # in 7 cells: more than INSERTION_MOST particles in each; in 100: a few
    cell_of = rng.integers(0, cells, n)
    coef = rng.uniform(1.0, 2.0, n) * 10.0 ** rng.integers(-8, 8, n)
    start_cpu, order_cpu = np.zeros(cells + 1, np.int64), np.zeros(n, np.int64)
    counting_sort(cell_of, cells, start_cpu, order_cpu)
    expected = np.zeros(cells)
    cell_coefficients(cell_of, coef, expected)
    reversed_sums = [sum(coef[cell_of == c][::-1], 0.0) for c in range(cells)]
    assert not np.array_equal(reversed_sums, expected)  # the order matters
    fullest = np.bincount(cell_of, minlength=cells).max()
    assert (fullest > cuda_porosity.INSERTION_MOST) == (cells == 7)

    count = cuda.to_device(np.zeros(cells, np.int32))
    start = cuda.to_device(np.zeros(cells + 1, np.int32))
    following = cuda.to_device(np.zeros(cells, np.int32))
    order = cuda.to_device(np.zeros(n, np.int32))

    def sort_by_cell():
        cuda_porosity.count_in_cells[3, 128](cell_of, count)
        cuda_porosity.cell_starts[1, 1](count, start, following)
        cuda_porosity.fill_cells[3, 128](cell_of, following, order)

    sort_by_cell()
    cuda_porosity.sort_cells[1, cells](start, order, count)
    assert np.array_equal(start.copy_to_host(), start_cpu) and np.array_equal(order.copy_to_host(), order_cpu)
    assert not count.copy_to_host().any()  # zeroed for the next sort
    bounds = start.copy_to_host()
    handed = order_cpu.astype(np.int32)
    for c in range(cells):
        handed[bounds[c] : bounds[c + 1]] = handed[bounds[c] : bounds[c + 1]][::-1].copy()
    found = np.zeros(cells)
    cuda_drag.cell_coefficients[1, cells](start, handed, coef, count, found)
    assert np.array_equal(found, expected)
    sort_by_cell()  # and as the kick sums them, from the device's own fill
    found[:] = 0.0
    cuda_drag.cell_coefficients[1, cells](start, order, coef, count, found)
    assert np.array_equal(found, expected)


# a 1D VANS water column over the floor, driven by a pressure gradient, solved every 10 steps,
# with turbulent fluctuations drawn at each and lift: the particles in it feel drag, buoyancy
# and lift from the profile on the device
VANS = """
[[walls]]
face = "z-"
material = "b"
[fluid]
model = "vans1d"
surface = 0.0075
cells = 15
coupling = { steps = 10 }
lift_coefficient = 0.2
buoyancy = "full"
flow = { kind = "solved", mixing_length = "prandtl", pressure_gradient = -2000.0, initial = "rest" }
fluctuations = { bed_elevation = 0.001, seed = 3 }
"""


# the cell-averaged Gidaspow drag, without the pressure-gradient force
NAVIER_STOKES_CELL_DRAG = NAVIER_STOKES.replace(
    "coupling =", 'drag = { law = "gidaspow", averaging = "cell", pressure_force = false }\ncoupling ='
)

# a lid coming down with the grid following it: the grid's cells change in the fluid's own step,
# before the porosity, so the particles come back for the host to measure it
NAVIER_STOKES_UNDER_A_LID = NAVIER_STOKES.replace(
    "[fluid]", '[[walls]]\nface = "z+"\nmode = "velocity"\nvelocity = -0.5\n[fluid]'
).replace("grid = { cells = [2, 2, 3] }", "grid = { cells = [2, 2, 3], follow_top_wall = true }")


# a grid of 3 x 2 columns, so that a GPU kernel taking a column's i for its j is seen
NAVIER_STOKES_3X2 = NAVIER_STOKES.replace("cells = [2, 2, 3]", "cells = [3, 2, 3]")


def _darcy_and_lid_fields(scene) -> dict:
    w = scene.state.walls
    return {**_darcy_fields(scene), "wall_coord": w.coord, "wall_fluid_force": w.fluid_force}


def _navier_stokes_fields(scene) -> dict:
    fs, drag = scene.fluid.fs, scene.fluid.drag
    fields = {
        "v": fs.v,
        "v_face": fs.v_face,
        "p": fs.p,
        "grad_p": fs.grad_p,
        "f_exchange": fs.f_exchange,
        "impulse": drag.impulse,
        "f_drag": drag.f_drag,
    }
    if drag.corrected:
        fields["self_induced"] = drag.disturbance
    return fields


def _vans_fields(scene) -> dict:
    f = scene.state.fluid
    return {"u": f.column.u, "drag_coef": f.drag_coef, "drag_x": f.drag_x}


def _spoil_the_column(scene) -> None:
    scene.state.fluid.column.u[3] = np.nan


def _spoil_the_grid(scene) -> None:
    scene.fluid.fs.p[1, 0, 2] = np.nan


@pytest.mark.parametrize(
    "fluid, brought_back, spoil, message",
    [
        (
            VANS,
            lambda s: s.state.fluid.drag_coef,
            _spoil_the_column,
            "vans1d fluid velocity is nan m/s in layer 3",
        ),
        # its test of the cells crossed a fluid step reads the particles' velocities
        (
            NAVIER_STOKES,
            lambda s: s.state.particles.vel,
            _spoil_the_grid,
            "has a non-finite pressure (nan Pa)",
        ),
    ],
    ids=["vans1d", "navier-stokes"],
)
def test_a_fluids_stability_is_checked_without_bringing_the_state_back(
    tmp_path, fluid, brought_back, spoil, message
):
    """With a fluid on the GPU, the stability check tests the particles on the device and the
    fluid on its host fields with only what its test reads brought back (the VANS drag, the
    particles' velocities); a fluid gone bad stops the run with the CPU's message."""
    from sphere_cli.errors import NumericalError
    from sphere_cli.simulation import check_stable

    gpu, cpu = _scenes(tmp_path, walls=fluid)
    advance(gpu, 12, sync=False)  # past the fluid step at 10, for whose step the host took some arrays
    advance(cpu, 12)
    check_stable(gpu)
    assert gpu.step.compiled.host_stale  # checked there: the list stayed on the device
    np.testing.assert_allclose(brought_back(gpu), brought_back(cpu), rtol=RTOL)
    messages = []
    for scene in (gpu, cpu):
        spoil(scene)
        with pytest.raises(NumericalError) as caught:
            check_stable(scene)
        messages.append(str(caught.value))
    assert messages[0] == messages[1] and message in messages[0]


def test_particles_under_the_porosity_floor_are_reported_from_the_gpu(tmp_path):
    """A porosity under fluid.drag.porosity_floor (0.1) in every cell, set between calls (the
    fluid's own step floors what it measures): the GPU counts the particles under it on the
    device and warns once at the next fluid step, the CPU at the step itself; the drag uses the
    floor on both."""
    gpu, cpu = _scenes(tmp_path, walls=NAVIER_STOKES)
    for scene in (gpu, cpu):
        advance(scene, 7)
        scene.fluid.fs.porosity[...] = 0.05
    with pytest.warns(RuntimeWarning, match=r"step 7: porosity 0.05 .*\(40 particle\(s\) this step, not"):
        advance(cpu, 5)
    with pytest.warns(
        RuntimeWarning,
        match=r"step 10: porosity 0.05 in fluid cell \(\d, \d, \d\) is below fluid.drag.porosity_floor = 0.1;"
        r" the drag uses the floor there \(120 particle-step\(s\) since the last fluid step, not repeated\)",
    ):
        advance(gpu, 5)
    _compare(gpu, cpu)


def _vans_and_lid_fields(scene) -> dict:
    w = scene.state.walls
    return {**_vans_fields(scene), "wall_coord": w.coord, "wall_shift": w.shift, "wall_force": w.force}


# a lid keeping a stress and sliding over the VANS column: steps the CPU's compiled loop does not
# take (moving walls with a fluid), the GPU does
SLIDING_LID = """
[[walls]]
face = "z+"
mode = "stress"
stress = 500.0
shear_axis = "x"
shear_velocity = 0.05
"""
VANS_UNDER_A_LID = VANS.replace("[fluid]", SLIDING_LID + "[fluid]")


# under an impermeable lid keeping a stress, which the grid follows: the pore pressure pushes the
# lid every step (with the undrained response to its move since the last fluid step)
DARCY_UNDER_A_LID = (
    DARCY.replace("[fluid]", '[[walls]]\nface = "z+"\nmode = "stress"\nstress = 500.0\nmass = 10.0\n[fluid]')
    .replace("grid = { cells = [2, 2, 3] }", "grid = { cells = [2, 2, 3], follow_top_wall = true }")
    .replace('top = { type = "pressure", pressure = 0.0 }', 'top = { type = "no-flow" }')
)


def _darcy_fields(scene) -> dict:
    s = scene.fluid.pore.state
    return {
        "pressure": s.pressure,
        "gradient": s.gradient,
        "porosity": s.porosity,
        "particle_velocity": s.particle_velocity,
    }


@pytest.mark.parametrize(
    "fluid, fields, runs",
    [
        (VANS, _vans_fields, (15, 25, 20)),
        (VANS_UNDER_A_LID, _vans_and_lid_fields, (15, 25, 20)),
        (DARCY, _darcy_fields, (12, 23, 25)),
        (DARCY_UNDER_A_LID, _darcy_and_lid_fields, (12, 23, 25)),
        (NAVIER_STOKES, _navier_stokes_fields, (12, 23, 6)),
        (NAVIER_STOKES_CELL_DRAG, _navier_stokes_fields, (12, 23, 6)),
        (NAVIER_STOKES_UNDER_A_LID, _navier_stokes_fields, (12, 23, 6)),
        (NAVIER_STOKES_3X2, _navier_stokes_fields, (12, 23, 6)),
    ],
    ids=[
        "vans1d",
        "vans1d-moving-lid",
        "darcy",
        "darcy-pushed-lid",
        "navier-stokes",
        "navier-stokes-cell-drag",
        "navier-stokes-lid",
        "navier-stokes-3x2",
    ],
)
def test_a_fluid_acts_on_the_gpu_as_on_the_cpu(tmp_path, fluid, fields, runs):
    """A fluid with the particles on the GPU: its own step (the VANS column, the Darcy pore
    pressure) taken at each coupling step from the particles brought back or from what the
    device measured of them, its force
    (drag, buoyancy, lift and fluctuations; the seepage force and buoyancy) on the device every
    step, from the fields sent up after each fluid step. The runs end inside and at the coupling
    intervals."""
    gpu, cpu = _scenes(tmp_path, walls=fluid)
    assert type(gpu.step.compiled).__name__ == "DeviceSteps"
    for steps in runs:
        advance(gpu, steps)
        advance(cpu, steps)
        _compare(gpu, cpu)
    a, b = fields(gpu), fields(cpu)
    for name, other in b.items():
        assert np.abs(other).max() > 0.0, name  # the fluid did act
        np.testing.assert_allclose(a[name], other, rtol=RTOL, atol=RTOL * np.abs(other).max(), err_msg=name)


@pytest.mark.parametrize(
    "fluid, measured",
    [
        (DARCY, lambda s: (s.fluid.pore.state.porosity, s.fluid.pore.state.particle_velocity)),
        (NAVIER_STOKES, lambda s: (s.fluid.fs.porosity,)),
    ],
    ids=["darcy", "navier-stokes"],
)
def test_a_fixed_grid_measures_the_particles_on_the_gpu(tmp_path, monkeypatch, fluid, measured):
    """On a grid that keeps its cells, what a fluid's own step reads of the particles (the
    porosity; Darcy's mean particle velocity too) is measured on the device at the end of the step
    before it: the particles do not come back for it, and the fields are the CPU's."""
    from sphere_cli.physics.device_steps import DeviceSteps

    gpu, cpu = _scenes(tmp_path, walls=fluid)

    def refused(self, state):
        raise AssertionError("the particles came back for the fluid's step")

    monkeypatch.setattr(DeviceSteps, "_particles_to_host", refused)
    advance(gpu, 12, sync=False)  # past the fluid step at 10
    advance(cpu, 12)
    for a, b in zip(measured(gpu), measured(cpu), strict=True):
        assert np.abs(b - b.flat[0]).max() > 0.0  # not uniform: the particles' own
        np.testing.assert_allclose(a, b, rtol=RTOL, atol=RTOL * np.abs(b).max())


CONFIGS = Path(__file__).parents[2] / "configs"


def test_every_example_case_runs_on_the_gpu():
    """Every case of configs/ is taken by the GPU (none refused for a module it does not run)."""
    from sphere_cli.config.load import load_case

    for path in sorted(CONFIGS.glob("*.toml")):
        loaded = load_case(path)
        loaded.case.simulation.device = "cuda"
        assert type(build_scene(loaded).step.compiled).__name__ == "DeviceSteps", path.name


def test_the_fluidized_bed_example_starts_on_the_gpu_as_on_the_cpu():
    """configs/fluidized-bed.toml as written (192 spheres, 64 of them fixed as a distributor,
    the Gidaspow drag, the fluid forced up through the bed) over its first fluid steps: the GPU's
    particles are the CPU's. (The per-particle drag of fluid-settling.toml is that of the small
    scenes above.)"""
    from sphere_cli.config.load import load_case

    scenes = []
    for device in ("cuda", "cpu"):
        loaded = load_case(CONFIGS / "fluidized-bed.toml")
        loaded.case.simulation.device = device
        scenes.append(build_scene(loaded))
        advance(scenes[-1], 12)
    _compare(*scenes)


def _system(shape, singular: bool, seed: int = 5):
    """A right-hand side, c (zero: the singular Navier-Stokes pressure) and face coefficients
    over two decades, on `shape`."""
    rng = np.random.default_rng(seed)
    nx, ny, nz = shape
    b = rng.normal(size=shape)
    c = np.zeros(shape) if singular else rng.uniform(0.5, 2.0, shape)
    faces = [rng.uniform(0.1, 10.0, s) for s in ((nx + 1, ny, nz), (nx, ny + 1, nz), (nx, ny, nz + 1))]
    return b, c, *faces


@pytest.mark.parametrize(
    "shape, periodic, boundaries, method, preconditioner, singular, scale, launch",
    [
        ((8, 8, 16), (True, True, False), ("no-flux", "no-flux"), "pcg", "multigrid", True, 1.0, (1, 1)),
        ((5, 4, 8), (True, False, False), ("dirichlet", "no-flux"), "pcg", "multigrid", False, 1.0, (2, 3)),
        ((6, 4, 5), (False, True, False), ("dirichlet", "no-flux"), "pcg", "jacobi", False, 1.0, (1, 1)),
        ((4, 4, 6), (True, False, False), ("no-flux", "dirichlet"), "pcg", "jacobi", False, 1e-200, (1, 1)),
        (
            (4, 3, 4),
            (False, False, False),
            ("dirichlet", "dirichlet"),
            "jacobi",
            "jacobi",
            False,
            1.0,
            (1, 1),
        ),
    ],
    ids=[
        "multigrid-singular",
        "multigrid-uncolourable",
        "diagonal-dirichlet",
        "diagonal-rescaled",
        "jacobi-method",
    ],
)
def test_the_pressure_solve_on_the_gpu_is_the_cpus(
    shape, periodic, boundaries, method, preconditioner, singular, scale, launch, monkeypatch
):
    """physics/fluid/device_poisson.py: the solver with its fields on the GPU (kernels/fluid/
    cuda_poisson.py: the CPU's column functions, a thread a column; every sum the CPU's exact
    sum of the same column sums) gives the CPU's iterates, so its iteration count, residual and
    solution: the multigrid V-cycle (red-black sweeps, a Jacobi-smoothed coarsest level) on the
    singular periodic pressure equation and on a grid whose odd periodic count leaves its finest
    level to Jacobi sweeps (of more than ONE_BLOCK_CELLS, set to 100: two launches a pair; the
    coarsest's in one launch of one block), there launched as 2 blocks of 3 threads (the one
    block's 3 threads waiting for each other between sweeps), the diagonal preconditioner with
    Dirichlet faces, a right-hand side of 1e-200 (rescaled by a power of two), the Jacobi
    method; one forward-Euler step (explicit_step); and a zero right-hand side. Bitwise under
    the simulator. On a GPU its fused multiply-adds round otherwise: both solutions then meet the
    relative residual 1e-12, so they differ by at most 2e-12 times the condition number (under
    400 for these systems, from their eigenvalues) times the solution's 2-norm, at most sqrt(cells)
    = 32 times its largest value: under 3e-8 of the largest value (1e-7 allowed)."""
    from sphere_cli.physics import device_steps
    from sphere_cli.physics.fluid import device_poisson
    from sphere_cli.physics.fluid.device_poisson import OnGpu, on_gpu
    from sphere_cli.physics.fluid.grid import FluidGrid
    from sphere_cli.physics.fluid.poisson import PoissonSolver

    monkeypatch.setattr(device_poisson, "ONE_BLOCK_CELLS", 100)
    if SIMULATED:  # (on a GPU, blocks of THREADS)
        monkeypatch.setattr(device_steps, "SIMULATOR_LAUNCH", launch)

    grid = FluidGrid(np.zeros(3), np.array([0.1, 0.12, 0.09]), shape, np.array(periodic))
    cpu = PoissonSolver(grid, *boundaries, method, 1e-12, 1000, preconditioner)  # a broken sum: fails fast
    gpu = on_gpu(cpu)
    assert (
        isinstance(gpu.on, OnGpu)
        and on_gpu(gpu) is gpu
        and gpu.describe() == cpu.describe() + " (on the GPU)"
    )
    assert (gpu.multigrid is not None) == (preconditioner == "multigrid")
    b, c, ax, ay, az = _system(shape, singular)
    b *= scale

    def same(one, other):
        if SIMULATED:
            assert np.array_equal(one, other)
        else:
            np.testing.assert_allclose(one, other, rtol=0.0, atol=1e-7 * np.abs(other).max())

    results = []
    for solver in (cpu, gpu):
        x = np.full(shape, 0.25 * scale)
        results.append((solver.solve(x, b, c, ax, ay, az, 1.5 * scale, -0.5 * scale), x))
    (on_cpu, x_cpu), (on_device, x_gpu) = results
    assert on_cpu.converged and on_cpu.iterations > 3 and np.abs(x_cpu).max() > 0.0
    same(x_gpu, x_cpu)
    if SIMULATED:
        assert on_device == on_cpu
    if not singular:
        steps = [np.full(shape, 2.0) for _ in range(2)]
        for solver, x in zip((cpu, gpu), steps, strict=True):
            solver.explicit_step(x, b, c, ax, ay, az, 1.0, -1.0)
        same(steps[1], steps[0])
    x = np.ones(shape)
    assert gpu.solve(x, np.zeros(shape), c, ax, ay, az) == PoissonResult(0, 0.0, True, 0.0) and not x.any()


@pytest.mark.parametrize(
    "settings, shape, periodic, mean_source, launch",
    [
        ({}, (3, 2, 5), (True, True, False), None, (1, 1)),
        (
            {
                "bottom": {"type": "pressure", "pressure": 50.0},
                "fixed_pressure": [{"lower": [0, 0, 0.3], "upper": [0.15, 0.2, 0.5], "pressure": 20.0}],
                "permeability": {"model": "constant", "value": 1e-10},
            },
            (4, 3, 5),
            (True, False, False),
            None,
            (2, 3),
        ),
        ({"top": {"type": "no-flow"}}, (3, 3, 4), (False, True, False), 0.7, (1, 1)),
        ({"time_scheme": "explicit"}, (3, 2, 4), (True, True, False), None, (1, 1)),
        ({"porosity_min": 0.35, "porosity_max": 0.45}, (2, 3, 4), (False, False, False), None, (1, 1)),
    ],
    ids=["kozeny-carman", "fixed-cells-constant-k", "mean-source", "explicit", "clamped"],
)
def test_the_darcy_step_on_the_gpu_is_the_cpus(settings, shape, periodic, mean_source, launch, monkeypatch):
    """physics/fluid/device_pore_pressure.py: a pore-pressure step with its fields on the GPU
    (kernels/fluid/cuda_pore_pressure.py: the CPU's column functions, a thread a column; the solve
    device_poisson.py's) from random porosities, rates and particle velocities: Kozeny-Carman on
    a periodic grid; fixed cells (eliminated, their faces cut) with a constant permeability and a
    pressure face, launched as 2 blocks of 3 simulated threads; the mean source of a grid
    following its top wall; the explicit scheme; porosities clamped in most cells, their count
    the CPU's. Bitwise under the simulator; on a GPU, _made_as_on_the_cpu."""
    from sphere_cli.config.fluid_darcy import DarcyFluid
    from sphere_cli.physics import device_steps
    from sphere_cli.physics.fluid.device_fields import FieldsOnGpu
    from sphere_cli.physics.fluid.device_pore_pressure import step_on_gpu
    from sphere_cli.physics.fluid.grid import FluidGrid
    from sphere_cli.physics.fluid.pore_pressure import PorePressure

    if SIMULATED:
        monkeypatch.setattr(device_steps, "SIMULATOR_LAUNCH", launch)
    config = DarcyFluid.model_validate({"model": "darcy", "solver": {"tolerance": 1e-12}, **settings})
    grid = FluidGrid(np.zeros(3), np.array([0.05, 0.07, 0.1]), shape, np.array(periodic))
    pores = [PorePressure(config, grid, 1e-9) for _ in range(2)]
    step_on_gpu(pores[0])
    assert isinstance(pores[0].on, FieldsOnGpu) and not isinstance(pores[1].on, FieldsOnGpu)
    rng = np.random.default_rng(2)
    explicit = config.time_scheme == "explicit"
    dt = 0.2 * pores[1].explicit_step_limit() if explicit else 1e-3
    pressure = rng.normal(0.0, 10.0, shape)
    # the second step from the pressure the first left, raised on the host between the steps (as
    # a script may: the device takes it up), the device's other arrays kept
    for step in range(2):
        inputs = {
            "porosity": rng.uniform(0.3, 0.5, shape),
            "porosity_rate": rng.normal(0.0, 1.0, shape),
            "particle_velocity": rng.normal(0.0, 0.01, shape + (3,)),
        }
        for pore in pores:
            for name, values in inputs.items():
                getattr(pore.state, name)[...] = values
            if step == 0:
                pore.state.pressure[...] = pressure
            else:
                pore.state.pressure[...] += 3.0
            pore.advance(dt, (step + 1) * dt, mean_source)
        gpu, cpu = (pore.state for pore in pores)
        assert gpu.clamped_cells == cpu.clamped_cells
        assert cpu.iterations > 0 or explicit
        assert (cpu.clamped_cells > shape[0] * shape[1]) == ("porosity_min" in settings)
        for name in STEP_OUTPUTS:
            assert np.abs(getattr(cpu, name)).max() > 0.0, name
            if SIMULATED:
                assert np.array_equal(getattr(gpu, name), getattr(cpu, name)), name
        if SIMULATED:
            assert gpu.iterations == cpu.iterations
        else:
            _made_as_on_the_cpu(*pores, (step + 1) * dt)


def _made_as_on_the_cpu(on_gpu, on_cpu, time: float) -> None:
    """On a GPU: the pressure within the solve's bound of the CPU's
    (test_the_pressure_solve_on_the_gpu_is_the_cpus: 1e-7 of its largest value, with room for
    the second step's start); what the step makes from the porosity and the pressure (the clamp,
    the permeability, the gradient, the Darcy velocity) the CPU kernels' from the same values to
    the round-off of fused multiply-adds (1e-12 of each field's largest value: a few operations a
    value)."""
    gpu, cpu = on_gpu.state, on_cpu.state
    np.testing.assert_allclose(gpu.pressure, cpu.pressure, rtol=0.0, atol=1e-7 * np.abs(cpu.pressure).max())
    check = copy.deepcopy(on_cpu)
    check.state.pressure[...] = gpu.pressure
    check.update_permeability()
    check.update_gradient(time)
    for name in STEP_OUTPUTS[1:]:
        a, b = getattr(gpu, name), getattr(check.state, name)
        np.testing.assert_allclose(a, b, rtol=0.0, atol=1e-12 * np.abs(b).max(), err_msg=name)


def test_a_gpu_run_steps_its_fluid_grid_on_the_gpu(tmp_path):
    """With the particles on the GPU (FluidModule.grid_on_gpu) the Navier-Stokes and Darcy grids
    take their steps there, the pressure solve included; the fluid's line of run.log (its
    summary) says so."""
    for name, fluid in (("darcy", DARCY), ("navier-stokes", NAVIER_STOKES)):
        (tmp_path / name).mkdir()
        gpu, cpu = _scenes(tmp_path / name, walls=fluid)
        on_gpu = [key for key, fact in gpu.fluid.summary().items() if "on the GPU" in fact]
        assert on_gpu == (["grid", "solver"] if name == "darcy" else ["fluid grid", "pressure solver"]), name
        assert not any("on the GPU" in fact for fact in cpu.fluid.summary().values())


@pytest.mark.parametrize(
    "fluid, state",
    [(DARCY, lambda s: s.fluid.pore.state), (NAVIER_STOKES, lambda s: s.fluid.fs)],
    ids=["darcy", "navier-stokes"],
)
def test_the_gpus_bytes_count_its_fluid_grid(tmp_path, fluid, state):
    """DeviceSteps.device_bytes (sphere bench gpu's memory per particle) counts what the fluid's
    grid keeps on the GPU: its pressure solve's fields from the start (seven grids at least),
    its step's fields (a device array for each of its state's) from its first step."""
    gpu, _ = _scenes(tmp_path, walls=fluid)
    advance(gpu, 3)  # before the first fluid step
    steps = gpu.step.compiled
    cells = gpu.fluid.grid().cell_count
    assert gpu.fluid.grid_device_bytes() >= 7 * 8 * cells
    before = steps.device_bytes()
    advance(gpu, 10)
    arrays = [a for a in vars(state(gpu)).values() if isinstance(a, np.ndarray)]
    assert steps.device_bytes() - before >= sum(a.nbytes for a in arrays)


def test_a_gpu_failure_in_the_pressure_solve_is_the_users_error(monkeypatch):
    """A CUDA error in a solve on the GPU (out of memory above all), which runs in the fluid's own
    step on the host, outside DeviceSteps.run, is a CaseError naming simulation.device (exit 65),
    not a traceback; any other error is left as it is."""
    from sphere_cli.errors import CaseError
    from sphere_cli.physics.fluid.device_poisson import OnGpu, on_gpu
    from sphere_cli.physics.fluid.grid import FluidGrid
    from sphere_cli.physics.fluid.poisson import PoissonSolver

    shape = (3, 3, 4)
    grid = FluidGrid(np.zeros(3), np.full(3, 0.1), shape, np.array([False, False, False]))
    gpu = on_gpu(PoissonSolver(grid, "dirichlet", "no-flux", "pcg", 1e-10, 100, "jacobi"))
    arguments = _system(shape, singular=False)
    out_of_memory = type("CudaAPIError", (Exception,), {"__module__": "numba.cuda.cudadrv.driver"})
    for error, expected in ((out_of_memory, CaseError), (ZeroDivisionError, ZeroDivisionError)):

        def fail(*_, error=error):
            raise error("CUDA_ERROR_OUT_OF_MEMORY")

        monkeypatch.setattr(OnGpu, "inputs", fail)
        for call in (gpu.solve, gpu.explicit_step):
            with pytest.raises(expected) as raised:
                call(np.zeros(shape), *arguments)
            if expected is CaseError:
                assert str(raised.value).startswith(
                    'simulation.device = "cuda": the GPU failed: CudaAPIError: CUDA_ERROR_OUT_OF_MEMORY'
                )


def test_a_non_finite_navier_stokes_step_on_the_gpu_says_where_as_on_the_cpu(tmp_path):
    """A Navier-Stokes step on the GPU that meets a non-finite input stops the run with the CPU's
    message, naming the quantity, the cell and the value (the fields it names brought back)."""
    from sphere_cli.errors import NumericalError

    gpu, cpu = _scenes(tmp_path, walls=NAVIER_STOKES)
    messages = []
    for scene in (gpu, cpu):
        fluid = scene.fluid
        fluid.fs.f_i[1, 0, 2, 1] = np.nan
        with pytest.raises(NumericalError) as raised:
            fluid.solver.step(fluid.fs, 0.0, fluid.fluid_dt)
        messages.append(str(raised.value))
    assert messages[0] == messages[1]
    assert "a non-finite interaction force density y (nan N/m^3) at fluid cell (1, 0, 2)" in messages[0]


def test_a_darcy_solve_that_fails_on_the_gpu_stops_the_run_as_on_the_cpu(tmp_path):
    """A pore-pressure solve on the GPU that does not converge (one iteration allowed) stops the
    run at the same step with the CPU's message, and the pressure it leaves on the host (what a
    run's last frame would show) is the CPU's."""
    from sphere_cli.errors import NumericalError

    text = DARCY.replace("tolerance = 1e-13 }", "tolerance = 1e-13, max_iterations = 1 }")
    gpu, cpu = _scenes(tmp_path, walls=text)
    messages = []
    for scene in (gpu, cpu):
        with pytest.raises(NumericalError) as raised:
            advance(scene, 12)
        messages.append(str(raised.value))
    assert messages[0] == messages[1]
    assert "at step 5 " in messages[0] and "did not converge" in messages[0]
    a, b = gpu.fluid.pore.state.pressure, cpu.fluid.pore.state.pressure
    np.testing.assert_allclose(a, b, rtol=RTOL, atol=RTOL * np.abs(b).max())
