"""Benchmark of the vans1d bedload case (never part of the tests): wall time per simulated second
of configs/bedload.toml and the share of it spent on the fluid's parts.

    python -m sphere_cli.bench_vans1d [--case configs/bedload.toml] [--threads 1,2] [--time 0.05]

For each thread count the scene is built afresh (the steady initial profile included, not
timed), advanced 200 steps to compile or load the kernels, then timed over `--time` simulated
seconds. The fluid's methods are wrapped with timers: the particle forces of every step
(kernels/fluid/profile_forces.py), the layer averaging of every coupling interval (drag coefficients
and kernels/fluid/layer_averaging.py) and the fluid resolution (kernels/fluid/vans1d.py).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numba

from .config.load import load_case
from .scene.builder import build_scene
from .simulation import advance


class Stopwatch:
    def __init__(self, function):
        self.function = function
        self.seconds = 0.0
        self.calls = 0

    def __call__(self, *args, **kwargs):
        start = time.perf_counter()
        result = self.function(*args, **kwargs)
        self.seconds += time.perf_counter() - start
        self.calls += 1
        return result


def measure(case: Path, threads: int, simulated: float) -> dict:
    numba.set_num_threads(threads)
    scene = build_scene(load_case(case))
    state, fluid = scene.state, scene.fluid
    advance(scene, 200)
    parts = {
        "fluid forces": Stopwatch(fluid.forces),
        "averaging": Stopwatch(fluid._average),
        "fluid resolution": Stopwatch(state.fluid.column.advance),
    }
    fluid.forces, fluid._average, state.fluid.column.advance = parts.values()
    scene.order_modules()  # the step's hooks taken anew: the timed forces
    steps = round(simulated / state.clock.dt)
    start = time.perf_counter()
    advance(scene, steps)
    wall = time.perf_counter() - start
    column = state.fluid.column
    return {
        "threads": threads,
        "steps": steps,
        "wall": wall,
        "per_simulated_second": wall / (steps * state.clock.dt),
        "particle_steps_per_second": steps * state.particles.count / wall,
        "cell_updates_per_second": parts["fluid resolution"].calls
        * fluid.fluid_steps
        * column.cells
        / max(parts["fluid resolution"].seconds, 1e-300),
        "shares": {name: watch.seconds / wall for name, watch in parts.items()},
    }


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", default="configs/bedload.toml")
    parser.add_argument("--threads", default="1,2")
    parser.add_argument("--time", type=float, default=0.05, help="simulated seconds timed [s]")
    args = parser.parse_args(argv)
    for threads in (int(t) for t in args.threads.split(",")):
        r = measure(Path(args.case), threads, args.time)
        shares = ", ".join(f"{name} {100 * share:.1f} %" for name, share in r["shares"].items())
        print(
            f"threads {threads}: {r['per_simulated_second']:.1f} s per simulated second "
            f"({r['steps']} steps in {r['wall']:.2f} s, {r['particle_steps_per_second'] / 1e6:.2f} M "
            f"particle-steps/s); {shares}; fluid solve {r['cell_updates_per_second'] / 1e6:.1f} M "
            "cell-updates/s",
            flush=True,
        )


if __name__ == "__main__":
    main()
