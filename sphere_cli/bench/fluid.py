"""`sphere bench fluid`: the porous Navier-Stokes fluid coupled to a DEM bed (the fluid's
benchmark; never part of the tests' timings).

The scene: a cube of `cells`^3 fluid cells of 2 mm (periodic in x and y), a bed of `particles`
quartz spheres of 1 mm diameter (darcy.py's particles, cells, contact law and dt: two
diameters a cell, so that a particle fills at most 1/8 of a cell's sampling sphere; k_n = 1e3 N/m,
dt = 4e-6 s) on the canonical scene's loose jittered lattice (dem.py: spacing 1.2 diameters)
filled from the floor: 11 236 a layer at 64^3, so 20 000 make a bed 2 layers (about 1 cell)
deep under 63 cells of water. Water, Gidaspow drag, an upward seepage of half the bed's buoyant
weight per area forced by the bottom pressure (top open at 0 Pa), one fluid step per DEM step
(fluid.coupling.steps = 1), the pressure solver and tolerance at their defaults (PCG with multigrid, 1e-10).

Reported, apart: the compile (or cache-load) time (an 8^3 scene with 200 particles: the same
kernels, the multigrid's and Jacobi's included), the build time and the first coupled step
(cold: the porosity of the bed and the pressure from hydrostatic). Then for each thread count the
median over `steps` coupled steps of: the coupled step, the fluid step (predictor, pressure
equation, correction) with its cell-updates per second, the pressure solve inside it (warm-started
from the previous step's pressure, its iterations), the porosity measure and the drag gather.
Jacobi against the fast solver: the pressure equation of the last timed step, from the same warm
start, solved again by both at the same tolerance; Jacobi stops at `jacobi_max_iterations` or
after `jacobi_seconds`, whichever comes first, and is then reported as not converged with its
iterations, time and residual.
"""

from __future__ import annotations

import math
import os
import statistics
import time
from pathlib import Path

import numba
import numpy as np

from ..config.load import parse_case
from ..io.json_text import json_text
from ..physics.fluid.poisson import PoissonSolver
from ..scene.builder import build_scene
from . import Stopwatch, machine, timed_steps
from .darcy import CELL, DENSITY, DIAMETER, scene_text
from .dem import SPACING

RADIUS = DIAMETER / 2.0  # [m]
WATER = 1000.0  # [kg/m^3]
GRAVITY = 9.81  # [m/s^2]
JACOBI_CHUNK = 200  # Jacobi iterations between checks of the time budget


def case_text(cells: int, particles: int) -> str:
    """The benchmark scene as case-file text (module docstring)."""
    width = cells * CELL
    solid_height = particles * 4.0 / 3.0 * math.pi * RADIUS**3 / width**2  # [m] of solid
    bottom = WATER * GRAVITY * width + 0.5 * (DENSITY - WATER) * GRAVITY * solid_height
    return (
        scene_text(cells, particles, SPACING, 1.0)
        + f"""[fluid]
model = "navier-stokes"
density = {WATER!r}
viscosity = 1.0e-3
grid = {{ cells = [{cells}, {cells}, {cells}] }}
bottom = {{ type = "pressure", pressure = {bottom!r} }}
top = {{ type = "pressure", pressure = 0.0 }}
[fluid.coupling]
steps = 1
"""
    )


class CapturingStopwatch(Stopwatch):
    """A Stopwatch on PoissonSolver.solve that, when `capture` is set, keeps a copy of the
    system of the next call (first guess, right-hand side, coefficients, boundary values)."""

    capture = False
    system: tuple | None = None

    def __call__(self, x, b, c, ax, ay, az, bottom_value=0.0, top_value=0.0):
        if self.capture:
            self.system = tuple(np.copy(a) for a in (x, b, c, ax, ay, az)) + (bottom_value, top_value)
            self.capture = False
        return super().__call__(x, b, c, ax, ay, az, bottom_value, top_value)


def _jacobi(fluid, max_iterations: int = 2) -> PoissonSolver:
    """The reference's Jacobi iteration for the pressure equation of `fluid` (NavierStokes), at
    its solver's tolerance."""
    solver = fluid.solver
    kinds = ["dirichlet" if k else "no-flux" for k in solver.p_kind]
    return PoissonSolver(fluid.grid(), kinds[0], kinds[1], "jacobi", solver.poisson.tolerance, max_iterations)


def _solve_again(solver, system, budget: float | None = None, cap: int | None = None) -> dict:
    """Solve the captured system again with `solver` from its first guess: iterations, wall time,
    relative residual, converged. With a budget [s] (and cap), in chunks of JACOBI_CHUNK
    iterations, each continuing from the last iterate (a stationary iteration: the same as not
    stopping), until converged, `cap` iterations or `budget` seconds."""
    x0, b, c, ax, ay, az, bottom, top = system
    x = x0.copy()
    start = time.perf_counter()
    if budget is None:
        result = solver.solve(x, b, c, ax, ay, az, bottom, top)
        iterations, residual, converged = result.iterations, result.residual, result.converged
    else:
        iterations = 0
        while True:
            solver.max_iterations = min(JACOBI_CHUNK, cap - iterations)
            result = solver.solve(x, b, c, ax, ay, az, bottom, top)
            iterations += result.iterations
            residual, converged = result.residual, result.converged
            if converged or iterations >= cap or time.perf_counter() - start >= budget:
                break
    return {
        "iterations": iterations,
        "seconds": time.perf_counter() - start,
        "residual": residual,
        "converged": bool(converged),
    }


def _solve_text(solve: dict, tolerance: float) -> str:
    if solve["converged"]:
        return f"{solve['iterations']} iterations, {solve['seconds']:.3g} s"
    return (
        f"did not converge in {solve['iterations']} iterations / {solve['seconds']:.3g} s "
        f"(relative residual {solve['residual']:.3g} > tolerance {tolerance:g})"
    )


def _row_text(row: dict, steps: int, tolerance: float) -> str:
    ms = {key: 1e3 * value for key, value in row.items() if key.endswith("seconds")}
    return (
        f"threads = {row['threads']} (median of {steps} steps):\n"
        f"  coupled step {ms['coupled_step_seconds']:.1f} ms (CPU {ms['coupled_step_cpu_seconds']:.1f} ms, "
        f"best {ms['best_coupled_step_seconds']:.1f} ms)\n"
        f"  fluid step {ms['fluid_step_seconds']:.1f} ms: "
        f"{row['fluid_cell_updates_per_second'] / 1e6:.2f} M cell-updates/s "
        f"({row['explicit_cell_updates_per_second'] / 1e6:.2f} M without the pressure solve)\n"
        f"  pressure solve {ms['pressure_solve_seconds']:.1f} ms, "
        f"{row['pressure_iterations']:.0f} iterations; "
        f"porosity {ms['porosity_seconds']:.1f} ms; drag gather {ms['drag_gather_seconds']:.1f} ms\n"
        f"  the last step's pressure equation again from its warm start, tolerance {tolerance:g}: "
        f"fast solver {_solve_text(row['fast_solver_same_system'], tolerance)}; "
        f"Jacobi {_solve_text(row['jacobi_same_system'], tolerance)}"
    )


def run_fluid_benchmark(
    cells: int = 64,
    particles: int = 20_000,
    threads=(1, 2),
    steps: int = 20,
    jacobi_max_iterations: int = 100_000,
    jacobi_seconds: float = 60.0,
    out_dir: Path = Path("bench-results"),
    log=print,
) -> dict:
    """Run the fluid benchmark (module docstring); write out_dir/bench-fluid.json and return it."""
    out_dir.mkdir(parents=True, exist_ok=True)
    max_threads = numba.config.NUMBA_NUM_THREADS
    results = {"case": "fluid", "machine": machine(), "load_average_before": list(os.getloadavg())}
    start = time.perf_counter()
    warm = build_scene(parse_case(case_text(8, 200)))  # 8^3: the multigrid's kernels too
    timed_steps(warm, 2)
    wf = warm.fluid.fs
    _jacobi(warm.fluid).solve(wf.eps.copy(), wf.rhs, wf.zero, wf.ax, wf.ay, wf.az)
    results["compile_seconds"] = time.perf_counter() - start
    results["threading_layer"] = numba.threading_layer()
    log(
        "compile / cache load of the kernels (an 8^3 scene, 2 steps, 2 Jacobi iterations): "
        f"{results['compile_seconds']:.2f} s; "
        f"{results['threading_layer']} threading layer; load average {results['load_average_before'][0]:.2f}"
    )

    start = time.perf_counter()
    scene = build_scene(parse_case(case_text(cells, particles)))
    scene.fluid.step_threads = None  # every part on the row's threads (runtime.grid_threads)
    results["build_seconds"] = time.perf_counter() - start
    fluid = scene.fluid
    solver, fs = fluid.solver, fluid.fs
    results["first_step_seconds"] = timed_steps(scene, 1)[0][0]
    results.update(
        particles=scene.state.particles.count,
        cells=list(fluid.grid().shape),
        cell_count=int(np.prod(fluid.grid().shape)),
        dt=scene.state.clock.dt,
        coupling_steps=fluid.coupling_steps,
        pressure_solver=solver.poisson.describe(),
        tolerance=solver.poisson.tolerance,
        first_step_iterations=fs.iterations,
        steps=steps,
        rows=[],
    )
    log(
        f"{results['cells'][0]}x{results['cells'][1]}x{results['cells'][2]} = {results['cell_count']} cells, "
        f"{results['particles']} particles, dt = {results['dt']:.3g} s, one fluid step per DEM step; "
        f"build {results['build_seconds']:.2f} s; first coupled step {results['first_step_seconds']:.2f} s "
        f"(cold porosity, pressure from hydrostatic: {fs.iterations} iterations); "
        f"pressure solver: {results['pressure_solver']}"
    )
    jacobi = _jacobi(fluid)
    med = statistics.median
    for t in threads:
        if t > max_threads:
            continue
        numba.set_num_threads(t)
        timed_steps(scene, 2)
        watches = {
            "fluid_step": Stopwatch(solver, "step"),
            "porosity": Stopwatch(fluid, "_measure_porosity"),
            "drag_gather": Stopwatch(fluid.drag, "fluid_forcing"),
        }
        solve = CapturingStopwatch(solver.poisson, "solve")
        iterations, wall, cpu = [], [], []
        for n in range(steps):
            solve.capture = n == steps - 1
            w, c = timed_steps(scene, 1)
            wall += w
            cpu += c
            iterations.append(fs.iterations)
        solve.restore()
        for watch in watches.values():
            watch.restore()
        fluid_step = med(watches["fluid_step"].seconds)
        solve_seconds = med(solve.seconds)
        explicit = med(f - p for f, p in zip(watches["fluid_step"].seconds, solve.seconds, strict=True))
        row = {
            "threads": t,
            "coupled_step_seconds": med(wall),
            "coupled_step_cpu_seconds": med(cpu),
            "best_coupled_step_seconds": min(wall),
            "fluid_step_seconds": fluid_step,
            "fluid_cell_updates_per_second": results["cell_count"] / fluid_step,
            "explicit_cell_updates_per_second": results["cell_count"] / explicit,
            "pressure_solve_seconds": solve_seconds,
            "pressure_iterations": med(iterations),
            "porosity_seconds": med(watches["porosity"].seconds),
            "drag_gather_seconds": med(watches["drag_gather"].seconds),
            "particle_steps_per_second": results["particles"] / med(wall),
        }
        row["fast_solver_same_system"] = _solve_again(solver.poisson, solve.system)
        row["jacobi_same_system"] = _solve_again(jacobi, solve.system, jacobi_seconds, jacobi_max_iterations)
        results["rows"].append(row)
        log(_row_text(row, steps, results["tolerance"]))
    numba.set_num_threads(max_threads)
    results["jacobi_limits"] = {"max_iterations": jacobi_max_iterations, "seconds": jacobi_seconds}
    results["load_average_after"] = list(os.getloadavg())
    (out_dir / "bench-fluid.json").write_text(json_text(results))
    log(
        f"load average {results['load_average_after'][0]:.2f} at the end; "
        f"results written to {out_dir / 'bench-fluid.json'}"
    )
    return results
