"""`sphere bench compile`: how long a dry scene waits for its kernels before the first step,
with an empty Numba cache (cold: every kernel compiled) and with the cache that run filled
(cached: every kernel loaded), each in a fresh process.

The scene is the canonical one of `sphere bench dem` with 256 spheres and six walls, on each of
the thread counts asked for: one thread compiles the serial kernels, more the parallel ones
(kernels/serial.py; a run of 200 spheres or more on several threads uses them). Timed in the
child from before `import sphere_cli` to the end of its first steps, taken both ways: many at a
time in the compiled loop (physics/compiled_steps.py) and one at a time through the hooks, so
that every kernel of a dry run is compiled or loaded (the neighbour build and its sort, the pair
and wall contacts, the kicks, the compiled loop). Python's start-up is not counted.
With a spare core, a cold run compiles half of those in a helper process (compile_ahead.py),
as any new run does; the first steps wait for it, so the figure includes it.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time

CHILD = """
import time
start = time.perf_counter()
import json
from sphere_cli.bench.dem import canonical_case
from sphere_cli.config.load import parse_case
from sphere_cli.scene.builder import build_scene
from sphere_cli.simulation import advance
scene = build_scene(parse_case(canonical_case(256)))
advance(scene, 20)
scene.step.compiled = None
advance(scene, 1)
print(json.dumps({"seconds": time.perf_counter() - start}))
"""


def _first_steps(cache: str, threads: int) -> float:
    env = {**os.environ, "NUMBA_CACHE_DIR": cache, "NUMBA_NUM_THREADS": str(threads)}
    out = subprocess.run([sys.executable, "-c", CHILD], env=env, capture_output=True, text=True, check=True)
    return float(json.loads(out.stdout.strip().splitlines()[-1])["seconds"])


def run_compile_benchmark(repeats: int = 1, threads: tuple[int, ...] = (1,), log=print) -> dict:
    """Cold and cached seconds of `repeats` fresh caches on each thread count, by count (module
    docstring); the counts alternate within a round."""
    results = {count: {"cold_seconds": [], "cached_seconds": []} for count in threads}
    for _ in range(repeats):
        for count in threads:
            with tempfile.TemporaryDirectory(prefix="sphere-numba-") as cache:
                t0 = time.perf_counter()
                cold, cached = _first_steps(cache, count), _first_steps(cache, count)
                results[count]["cold_seconds"].append(cold)
                results[count]["cached_seconds"].append(cached)
                log(
                    f"kernels of a dry scene on {count} thread{'s' if count > 1 else ''}: cold {cold:.1f} s, "
                    f"cached {cached:.2f} s (round of {time.perf_counter() - t0:.0f} s)"
                )
    return results
