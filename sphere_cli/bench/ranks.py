"""`sphere bench ranks`: the canonical settled bed of `sphere bench dem` (bench/dem.py) stepped on
1, 2, ... MPI ranks (physics/rank_steps.py), one thread each, side by side: the rank counts
alternate round by round (this machine's speed drifts by tens of per cent between minutes), and
each round's speed-up over one rank is reported with its spread. With `walls` "moving" the
bed's lid keeps a stress and slides (bench/dem.py MOVING_LID, put down onto the bed) and its x+
and y+ walls keep PRESSED_SIDES: the walls' steps and the particles' pushes on them summed over
the ranks, each step.

A timing is one call of advance as the run loop makes it between two outputs (the ranks'
steps), after one such call and one gather untimed; the gather of the state at the lead that an output then
needs is timed apart. Each rank count runs in its own `mpiexec -n K python -m sphere_cli bench
ranks-member` process group, which prints its timings as one JSON line.
"""

from __future__ import annotations

import itertools
import json
import os
import shutil
import statistics
import subprocess
import sys
import time
from pathlib import Path

from ..errors import MissingInputError
from ..io.json_text import json_text
from . import machine
from .dem import settled_scene


def mpiexec() -> str:
    """The launcher beside this Python (the mpich wheel), else the first on PATH."""
    beside = Path(sys.executable).with_name("mpiexec")
    found = str(beside) if beside.is_file() else shutil.which("mpiexec")
    if found is None:
        raise MissingInputError(
            "sphere bench ranks: no mpiexec beside this Python or on PATH (pip install mpich, or load "
            "your site's MPI module)"
        )
    return found


def member(n: int, steps: int, repeats: int, lid: str = "fixed") -> None:
    """One rank count's timings (run under mpiexec; the lead prints them)."""
    from .. import ranks
    from ..simulation import advance, to_host

    world = ranks.start()
    if world is not None and not world.leads:
        raise SystemExit(world.follow())
    with ranks.leading(world):
        scene = settled_scene(n, log=lambda *_: None, lid=lid)
        # kernels loaded, the scene shared out, and (most likely) a list build of the parts: the
        # first loads its kernels from Numba's cache on each rank, 0.1 s once a run; so does
        # the first gather (its kernels placing the rows at the lead: 20-30 ms once)
        advance(scene, steps, sync=False)
        to_host(scene)
        times, gathers = [], []
        for _ in range(repeats):
            started = time.perf_counter()
            advance(scene, steps, sync=False)
            stepped = time.perf_counter()
            to_host(scene)
            times.append(stepped - started)
            gathers.append(time.perf_counter() - stepped)
        timing = {"ranks": ranks.count(), "n": n, "steps": steps, "seconds": times, "gather_seconds": gathers}
        print(json.dumps(timing), flush=True)


def time_on_ranks(launcher: str, k: int, n: int, steps: int, repeats: int, lid: str = "fixed") -> dict:
    """One `member` run on k ranks of one thread each, in its own process group: its timings
    (also benchmarks/peers/compare.py, beside the peers' ranks)."""
    env = {**os.environ, "NUMBA_NUM_THREADS": "1", "OMP_WAIT_POLICY": "PASSIVE"}
    command = [launcher, "-n", str(k), sys.executable, "-m", "sphere_cli", "bench", "ranks-member"]
    command += [str(n), str(steps), str(repeats), "--lid", lid]
    done = subprocess.run(command, capture_output=True, text=True, env=env)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def run_ranks_benchmark(
    sizes=(100_000,),
    rank_counts=(1, 2),
    steps: int = 100,
    repeats: int = 3,
    rounds: int = 3,
    out_dir: Path = Path("bench-results"),
    log=print,
    walls=("fixed",),
) -> dict:
    out_dir.mkdir(parents=True, exist_ok=True)
    launcher = mpiexec()
    results = {"machine": machine(), "steps": steps, "repeats": repeats, "rounds": rounds, "rows": []}
    for n, lid in itertools.product(sizes, walls):
        settled_scene(n, log)  # settled once here (cached), before any timing
        seconds = {k: [] for k in rank_counts}
        gathers = {k: [] for k in rank_counts}
        for round_ in range(rounds):
            for k in rank_counts:
                timing = time_on_ranks(launcher, k, n, steps, repeats, lid)
                seconds[k].append(statistics.median(timing["seconds"]))
                gathers[k].append(statistics.median(timing["gather_seconds"]))
                rate = n * steps / seconds[k][-1] / 1e6
                log(f"N = {n}, {lid} lid, round {round_ + 1}, {k} rank(s): {rate:.2f} M/s")
        for k in rank_counts:
            speedups = [one / many for one, many in zip(seconds[rank_counts[0]], seconds[k], strict=True)]
            row = {
                "n": n,
                "walls": lid,
                "ranks": k,
                "threads_per_rank": 1,
                "seconds": seconds[k],
                "particle_steps_per_second": n * steps / statistics.median(seconds[k]),
                "speedup_over_first": statistics.median(speedups),
                "speedup_range": [min(speedups), max(speedups)],
                "gather_seconds": statistics.median(gathers[k]),
            }
            results["rows"].append(row)
            log(
                f"N = {n}, {lid} lid: {k} rank(s) {row['particle_steps_per_second'] / 1e6:.2f} M "
                "particle-steps/s, "
                f"{row['speedup_over_first']:.2f} x {rank_counts[0]} rank(s) "
                f"({min(speedups):.2f}-{max(speedups):.2f}, round by round); the state to rank 0 for "
                f"an output: {row['gather_seconds'] * 1e3:.0f} ms"
            )
    (out_dir / "ranks.json").write_text(json_text(results) + "\n")
    return results
