"""Benchmark of the vans1d bedload case (never part of the tests): wall time per simulated second
of configs/bedload.toml and the share of it spent on the fluid's parts.

    sphere bench vans1d [--case configs/bedload.toml] [--threads 1,2] [--time 0.05]

For each thread count the scene is built afresh (the steady initial profile included, not
timed), advanced 200 steps to compile or load the kernels, then timed over `--time` simulated
seconds. For the shares, a further quarter of that is run with the fluid's methods wrapped in
timers (which keeps the step-by-step loop, physics/compiled_steps.py): the particle forces of every step
(kernels/fluid/profile_forces.py), the layer averaging of every coupling interval (drag coefficients
and kernels/fluid/layer_averaging.py) and the fluid resolution (kernels/fluid/vans1d.py).
"""

from __future__ import annotations

import time
from pathlib import Path

import numba

from ..config.load import load_case
from ..scene.builder import build_scene
from ..simulation import advance
from . import Stopwatch


def measure(case: Path, threads: int, simulated: float) -> dict:
    numba.set_num_threads(threads)
    scene = build_scene(load_case(case))
    state, fluid = scene.state, scene.fluid
    advance(scene, 200)
    steps = state.clock.steps_in(simulated)
    start = time.perf_counter()
    advance(scene, steps)
    wall = time.perf_counter() - start
    # the shares from a further quarter of the steps with the stopwatches on: a wrapped hook
    # keeps the step-by-step loop (physics/compiled_steps.py), so they are not in the timing above
    parts = {
        "fluid forces": Stopwatch(fluid, "forces", scene),
        "averaging": Stopwatch(fluid, "_average"),
        "fluid resolution": Stopwatch(state.fluid.column, "advance"),
    }
    start = time.perf_counter()
    advance(scene, max(1, steps // 4))
    watched = time.perf_counter() - start
    column = state.fluid.column
    return {
        "threads": threads,
        "steps": steps,
        "wall": wall,
        "per_simulated_second": wall / (steps * state.clock.dt),
        "particle_steps_per_second": steps * state.particles.count / wall,
        "cell_updates_per_second": len(parts["fluid resolution"].seconds)
        * fluid.fluid_steps
        * column.cells
        / max(sum(parts["fluid resolution"].seconds), 1e-300),
        "shares": {name: sum(watch.seconds) / watched for name, watch in parts.items()},
    }


def run_vans1d_benchmark(case: Path, threads=(1, 2), simulated: float = 0.05, log=print) -> None:
    """Log one row per thread count (module docstring)."""
    for count in threads:
        r = measure(case, count, simulated)
        shares = ", ".join(f"{name} {100 * share:.1f} %" for name, share in r["shares"].items())
        log(
            f"threads {count}: {r['per_simulated_second']:.1f} s per simulated second "
            f"({r['steps']} steps in {r['wall']:.2f} s, {r['particle_steps_per_second'] / 1e6:.2f} M "
            f"particle-steps/s); {shares}; fluid solve {r['cell_updates_per_second'] / 1e6:.1f} M "
            "cell-updates/s"
        )
