"""Benchmarks of the shared fluid plumbing (never part of the tests): the Poisson solver
(physics/fluid/poisson.py), iterations and time of "pcg" and "jacobi" at the same tolerance, and the
porosity estimate (physics/fluid/porosity.py).

    sphere bench grid [--sizes 32,64] [--threads 1,2] [--tolerance 1e-8]
    sphere bench grid --porosity [--threads 1,2]

The problem is the pressure equation of the Navier-Stokes model: -div(a grad x) = b on the unit
cube, periodic in x and y, Dirichlet (x = 0) at the bottom face, no-flux at the top, c = 0, from
x = 0. Two coefficient fields: a = 1 (the plain Poisson equation) and a "porosity" a drawn
uniformly in [0.35, 1] per cell (seed 1) with harmonic face means. b is a smooth mode plus
white noise (seed 1), so every wavelength is present. Times are the best of `repeats` solves
after two iterations that compile or load the kernels.

Porosity: 20 000 spheres of radius 1 mm at random (non-overlapping not needed for timing) in the
lower 30 % of a 64 x 64 x 64 grid of 2 mm cells (the cell edge at the limit of one diameter),
periodic in x and y; time of one measure() with the mean velocity and diameter, best of 5.
"""

from __future__ import annotations

import time

import numba
import numpy as np

from ..kernels.fluid.poisson import face_means
from ..physics.fluid.grid import FluidGrid
from ..physics.fluid.poisson import PoissonSolver
from ..physics.fluid.porosity import Porosity


def problem(n: int, variable: bool):
    grid = FluidGrid(np.zeros(3), np.full(3, 1.0 / n), (n, n, n), np.array([True, True, False]))
    x, y, z = (grid.centres(a) for a in range(3))
    rng = np.random.default_rng(1)
    b = np.sin(2 * np.pi * x)[:, None, None] * np.cos(2 * np.pi * y)[None, :, None] * np.sin(np.pi * z)
    b = b + 0.1 * rng.standard_normal(grid.shape)
    cell = rng.uniform(0.35, 1.0, grid.shape) if variable else np.ones(grid.shape)
    return grid, b, cell


def time_solve(grid, b, cell, method, preconditioner, tolerance, repeats):
    solver = PoissonSolver(
        grid, "dirichlet", "no-flux", method, tolerance, max_iterations=10**6, preconditioner=preconditioner
    )
    ax, ay, az = solver.face_arrays()
    face_means(cell, np.uint8(1), np.uint8(1), np.uint8(1), ax, ay, az)
    c = np.zeros(grid.shape)
    x = np.zeros(grid.shape)
    # compile (or load) the kernels with two iterations, so the timed solves measure the method
    PoissonSolver(grid, "dirichlet", "no-flux", method=method, max_iterations=2).solve(x, b, c, ax, ay, az)
    best, best_cpu = np.inf, np.inf
    for _ in range(repeats):
        x[:] = 0.0
        start, start_cpu = time.perf_counter(), time.process_time()
        result = solver.solve(x, b, c, ax, ay, az)
        best = min(best, time.perf_counter() - start)
        best_cpu = min(best_cpu, time.process_time() - start_cpu)
    return result, best, best_cpu


def porosity_benchmark(threads=(1, 2), repeats: int = 5, log=print) -> None:
    from types import SimpleNamespace

    n, edge, count = 64, 2e-3, 20_000
    grid = FluidGrid(np.zeros(3), np.full(3, edge), (n, n, n), np.array([True, True, False]))
    rng = np.random.default_rng(1)
    pos = rng.uniform(0.0, 1.0, (count, 3)) * [n * edge, n * edge, 0.3 * n * edge]
    particles = SimpleNamespace(pos=pos, vel=rng.standard_normal((count, 3)), radius=np.full(count, 1e-3))
    porosity = Porosity(grid, count)
    phi, vbar, dbar = np.zeros(grid.shape), np.zeros(grid.shape + (3,)), np.zeros(grid.shape)
    log("porosity: 64^3 cells, 20 000 particles | threads | wall ms | CPU ms per measure")
    for t in threads:
        numba.set_num_threads(t)
        porosity.measure(particles, phi, vbar, dbar)
        best, best_cpu = np.inf, np.inf
        for _ in range(repeats):
            start, start_cpu = time.perf_counter(), time.process_time()
            porosity.measure(particles, phi, vbar, dbar)
            best = min(best, time.perf_counter() - start)
            best_cpu = min(best_cpu, time.process_time() - start_cpu)
        log(f"porosity | {t} | {1e3 * best:.1f} | {1e3 * best_cpu:.1f}")


METHODS = ("pcg-multigrid", "pcg-jacobi", "jacobi")


def solver_benchmark(
    sizes=(32, 64), threads=(1, 2), tolerance: float = 1e-8, repeats: int = 3, methods=METHODS, log=print
) -> None:
    """Log, for each size, coefficient field, method and thread count, the solve of the module
    docstring: iterations, wall and CPU time, CPU time per iteration and cell-updates per CPU s."""
    log(f"numba {numba.__version__}, threading layer after first use; tolerance {tolerance:g}")
    log(
        "n^3 | coefficient | method | threads | iterations | wall [s] | CPU [s] | CPU ms/iteration"
        " | M cell-updates/CPU s"
    )
    for n in sizes:
        for variable in (False, True):
            grid, b, cell = problem(n, variable)
            for method in methods:
                for count in threads:
                    numba.set_num_threads(count)
                    name, _, preconditioner = method.partition("-")
                    result, wall, cpu = time_solve(
                        grid, b, cell, name, preconditioner or "jacobi", tolerance, repeats
                    )
                    its = max(result.iterations, 1)
                    log(
                        f"{n}^3 | {'porosity' if variable else 'a = 1'} | {method} | {count} | "
                        f"{result.iterations} | {wall:.3f} | {cpu:.3f} | {1e3 * cpu / its:.2f} | "
                        f"{n**3 * its / cpu / 1e6:.1f}"
                    )
