"""The state gathered at the lead before an output on ranks (physics/rank_steps.py to_host: the
owners' particles, rows and springs into the lead's whole scene), timed: the settled canonical
bed of `sphere bench ranks`, a few steps between gathers so that each has something to gather.

    mpiexec -n 2 python benchmarks/ranks/gathers.py [N] [gathers] [steps between]

(with OMP_WAIT_POLICY=PASSIVE NUMBA_NUM_THREADS=1, as `sphere bench ranks` runs its members).
Prints each gather's milliseconds and their median."""

import statistics
import sys
import time

from sphere_cli import ranks
from sphere_cli.bench.dem import settled_scene
from sphere_cli.simulation import advance, to_host


def main(n: int, gathers: int, steps: int) -> None:
    world = ranks.start()
    if world is None:
        raise SystemExit("start it under mpiexec: one process has nothing to gather")
    if not world.leads:
        raise SystemExit(world.follow())
    with ranks.leading(world):
        scene = settled_scene(n, log=lambda *_: None)
        advance(scene, steps, sync=False)
        to_host(scene)  # the first loads the kernels
        seconds = []
        for _ in range(gathers):
            advance(scene, steps, sync=False)
            started = time.perf_counter()
            to_host(scene)
            seconds.append(time.perf_counter() - started)
        print(f"{ranks.count()} rank(s), {n} particles: gathers [ms]", [round(1e3 * s, 1) for s in seconds])
        print(f"median {1e3 * statistics.median(seconds):.1f} ms", flush=True)


if __name__ == "__main__":
    arguments = [int(a) for a in sys.argv[1:]]
    main(*(arguments + [100_000, 20, 5][len(arguments) :]))
