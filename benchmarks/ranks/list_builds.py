"""Where a split run's steps go: the settled canonical bed of `sphere bench ranks` stepped on the
ranks of this launch, each list build (physics/rank_steps.py RankSteps._rebuild: the cut, the
particles sent to their owners and holders, the list built again) timed apart from the steps
between, and the builds' own functions profiled on the lead.

    mpiexec -n 2 python benchmarks/ranks/list_builds.py [N] [steps per timing] [timings]

(with OMP_WAIT_POLICY=PASSIVE NUMBA_NUM_THREADS=1, as `sphere bench ranks` runs its members).
On one process it times the one-rank list build (physics/neighbors.py NeighborSearch.rebuild)
instead. Prints each timing of the steps, each build's seconds on every rank, the median timing
without a build and with one, and on the lead the functions taking most of the builds after
the first (which shares the scene out)."""

import cProfile
import io
import pstats
import statistics
import sys
import time

from sphere_cli import ranks
from sphere_cli.bench.dem import settled_scene
from sphere_cli.physics import neighbors, rank_steps
from sphere_cli.simulation import advance, to_host

builds: list[float] = []
profile = cProfile.Profile()


def timed(owner, name: str, profiled: bool) -> None:
    """Replace owner.name by a version that records its seconds (and profiles it after the
    first call, where `profiled`)."""
    original = getattr(owner, name)

    def wrapper(*arguments):
        started = time.perf_counter()
        if profiled and builds:
            profile.enable()
        try:
            return original(*arguments)
        finally:
            profile.disable()
            builds.append(time.perf_counter() - started)

    setattr(owner, name, wrapper)


def main(n: int, steps: int, timings: int) -> None:
    world = ranks.start()
    if world is None:
        timed(neighbors.NeighborSearch, "rebuild", profiled=False)
    else:
        timed(rank_steps.RankSteps, "_rebuild", profiled=True)
        if not world.leads:
            code = world.follow()
            print(f"rank {world.rank}: list builds [s]", [round(b, 4) for b in builds], flush=True)
            raise SystemExit(code)
    with ranks.leading(world):
        scene = settled_scene(n, log=lambda *_: None)
        advance(scene, steps, sync=False)
        seconds, built = [], []
        for _ in range(timings):
            before = len(builds)
            started = time.perf_counter()
            advance(scene, steps, sync=False)
            seconds.append(time.perf_counter() - started)
            built.append(len(builds) > before)
        to_host(scene)
        print(f"{ranks.count()} rank(s), {n} particles: {steps} steps [s]", [round(s, 3) for s in seconds])
        print("rank 0: list builds [s]", [round(b, 4) for b in builds], flush=True)
        for label, holds in (("without", False), ("with", True)):
            chosen = [s for s, b in zip(seconds, built, strict=True) if b == holds]
            if chosen:
                print(f"timings {label} a build: {len(chosen)}, median {statistics.median(chosen):.4f} s")
        if world is not None:
            text = io.StringIO()
            pstats.Stats(profile, stream=text).sort_stats("tottime").print_stats(20)
            print(text.getvalue())


if __name__ == "__main__":
    arguments = [int(a) for a in sys.argv[1:]]
    main(*(arguments + [100_000, 100, 10][len(arguments) :]))
