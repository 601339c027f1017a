"""The pressure solve on the GPU against the processor's, side by side (docs/performance.md, "The
GPU"): physics/fluid/poisson.py PoissonSolver on the processor (all its threads) and with its
fields on the GPU (physics/fluid/device_poisson.py), on the Navier-Stokes pressure equation of a
periodic grid (singular, no-flux bottom and top: the multigrid V-cycle) and on Darcy's (c > 0, a
Dirichlet bottom), coefficients over two decades, from zero to the tolerance 1e-10; alternating,
medians of `rounds`. Prints each grid's iterations, both times, their ratio and the largest
difference of the solutions relative to the largest value (round-off times the condition number:
the GPU's fused multiply-adds).

    NUMBA_ENABLE_CUDASIM=0 python benchmarks/gpu_solve.py [rounds] [grids, e.g. 32x32x64,64x64x64]
"""

import sys
import time

import numpy as np

from sphere_cli.physics.fluid.device_poisson import on_gpu
from sphere_cli.physics.fluid.grid import FluidGrid
from sphere_cli.physics.fluid.poisson import PoissonSolver, preconditioner_for


def system(shape, singular: bool):
    rng = np.random.default_rng(1)
    nx, ny, nz = shape
    c = np.zeros(shape) if singular else rng.uniform(0.5, 2.0, shape)
    faces = [rng.uniform(0.1, 10.0, s) for s in ((nx + 1, ny, nz), (nx, ny + 1, nz), (nx, ny, nz + 1))]
    return rng.normal(size=shape), c, *faces


def main(rounds: int, grids: list) -> None:
    for shape in grids:
        grid = FluidGrid(np.zeros(3), np.full(3, 0.01), shape, np.array([True, True, False]))
        for name, boundaries, singular in (
            ("pressure", ("no-flux", "no-flux"), True),
            ("darcy", ("dirichlet", "no-flux"), False),
        ):
            cpu = PoissonSolver(grid, *boundaries, "pcg", 1e-10, 10_000, preconditioner_for(grid))
            gpu = on_gpu(cpu)
            arguments = system(shape, singular)
            seconds = {"cpu": [], "gpu": []}
            solutions = {}
            for _ in range(rounds + 1):  # the first compiles
                for place, solver in (("cpu", cpu), ("gpu", gpu)):
                    x = np.zeros(shape)
                    started = time.perf_counter()
                    result = solver.solve(x, *arguments)
                    seconds[place].append(time.perf_counter() - started)
                    solutions[place] = (x, result.iterations)
            (x_cpu, n_cpu), (x_gpu, n_gpu) = solutions["cpu"], solutions["gpu"]
            t_cpu, t_gpu = (float(np.median(seconds[p][1:])) for p in ("cpu", "gpu"))
            difference = float(np.abs(x_gpu - x_cpu).max() / np.abs(x_cpu).max())
            print(
                f"{'x'.join(map(str, shape))} {name}: iterations cpu {n_cpu} gpu {n_gpu}; "
                f"cpu {t_cpu * 1e3:.2f} ms, gpu {t_gpu * 1e3:.2f} ms, cpu/gpu {t_cpu / t_gpu:.2f}; "
                f"largest difference {difference:.2e} of the largest value",
                flush=True,
            )


if __name__ == "__main__":
    rounds = int(sys.argv[1]) if len(sys.argv) > 1 else 5
    text = sys.argv[2] if len(sys.argv) > 2 else "32x32x64,64x64x64,128x128x128"
    main(rounds, [tuple(int(n) for n in g.split("x")) for g in text.split(",")])
