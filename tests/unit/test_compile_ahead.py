"""Kernels compiled ahead in a helper process on an empty cache (sphere_cli/compile_ahead.py): the
helper compiles exactly what the run then loads instead of compiling it, and nothing starts where
the cache already holds the kernels or no core is spare."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

import numba
import pytest

from sphere_cli import compile_ahead
from sphere_cli.bench.dem import canonical_case
from sphere_cli.config.load import load_case, parse_case
from sphere_cli.errors import SphereError
from sphere_cli.scene.builder import build_scene
from sphere_cli.simulation import advance


@pytest.mark.parametrize("n", [64, 256])  # the serial twins below 200 particles on one thread
def test_the_jobs_are_the_kernels_the_run_compiles(n):
    scene = build_scene(parse_case(canonical_case(n)))
    jobs = compile_ahead.helper_jobs(scene) + compile_ahead.own_jobs(scene)
    scene.step.compiled = None  # the hooks call each kernel itself (a cached loop calls its own copies)
    advance(scene, 30)
    assert len(jobs) >= 5  # the build, the kick-drift, the kick, the walls, the pair sweep
    for kernel, arguments in jobs:
        assert compile_ahead._signature(kernel, arguments) in kernel.signatures, kernel


def test_on_one_thread_the_serial_twins_are_compiled_not_the_parallel_kernels(monkeypatch):
    """A run on one thread calls the serial twins (kernels/serial.py): the pair sweep compiled
    ahead, and the walls' forces measured for the observables, are those, not the parallel
    kernels (the parallel sweep alone took 11 s of a cold run's compiling and never ran)."""
    from sphere_cli.kernels.contact import chunk_pair_forces, chunk_pair_forces_serial
    from sphere_cli.physics import walls as wall_module
    from sphere_cli.runtime import threads_set_to

    scene = build_scene(parse_case(canonical_case(64)))

    def parallel_walls(*arguments):
        raise AssertionError("the parallel wall kernel was called")

    monkeypatch.setattr(wall_module, "wall_forces", parallel_walls)
    with threads_set_to(1):
        assert compile_ahead.own_jobs(scene)[-1][0] is chunk_pair_forces_serial
        scene.walls.measure(scene.state)
    if numba.config.NUMBA_NUM_THREADS > 1:
        with threads_set_to(2):
            assert compile_ahead.own_jobs(scene)[-1][0] is chunk_pair_forces
            with pytest.raises(AssertionError, match="parallel wall kernel"):
                scene.walls.measure(scene.state)


def test_nothing_starts_on_a_filled_cache():
    scene = build_scene(parse_case(canonical_case(64)))  # its kernels are in the cache now
    assert compile_ahead.start(scene, busy=0.0) is None


@pytest.mark.parametrize(
    ("busy", "cores", "spare"),
    [(0.0, 2, True), (0.2, 2, True), (1.0, 2, False), (None, 8, False), (0.0, 1, False)],
)
def test_the_helper_needs_a_spare_core(busy, cores, spare):
    assert compile_ahead.spare_core(busy, cores) is spare


# a dry scene built on an empty cache with a spare core (the sample of busy cores replaced)
COLD_RUN = """
import json
from sphere_cli import compile_ahead, runtime
from sphere_cli.bench.dem import canonical_case
from sphere_cli.config.load import parse_case
from sphere_cli.scene.builder import build_scene
from sphere_cli.simulation import advance

runtime.measure_busy_cores = lambda: 0.0
started = []
start = compile_ahead.start
compile_ahead.start = lambda scene: started.append(start(scene)) or started[-1]
scene = build_scene(parse_case(canonical_case(256)))
advance(scene, 5)
helper = started[0]
def counts(jobs, what):
    return {k.py_func.__name__: sum(getattr(k.stats, what).values()) for k, _ in jobs}
print(json.dumps({
    "started": helper is not None,
    "helper_exit": None if helper is None else helper.returncode,
    "loaded": counts(compile_ahead.helper_jobs(scene), "cache_hits"),
    "compiled": counts(compile_ahead.own_jobs(scene), "cache_misses"),
}))
"""


def test_a_cold_run_loads_what_its_helper_compiled(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path), "NUMBA_NUM_THREADS": "1"}
    command = [sys.executable, "-c", COLD_RUN]
    done = subprocess.run(command, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    report = json.loads(done.stdout.strip().splitlines()[-1])
    assert report["started"] and report["helper_exit"] == 0
    # each of the helper's kernels came from the cache here, the pair sweep was compiled here
    assert set(report["loaded"]) == {"build_lists", "kick_drift", "kick", "wall_forces"}
    assert all(hits == 1 for hits in report["loaded"].values()), report
    assert report["compiled"] == {"chunk_pair_forces": 1}


def test_a_refused_packing_stops_the_helper_at_once(monkeypatch, tmp_path):
    # a helper still compiling when the packing is refused (two spheres half a radius into each other)
    helper = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
    monkeypatch.setattr(compile_ahead, "start", lambda scene: helper)
    (tmp_path / "two.csv").write_text("x,y,z\n0.010,0.01,0.01\n0.0115,0.01,0.01\n")
    (tmp_path / "case.toml").write_text(OVERLAPPING)
    started = time.perf_counter()
    with pytest.raises(SphereError, match="overlap"):
        build_scene(load_case(tmp_path / "case.toml"))
    assert helper.poll() is not None and time.perf_counter() - started < 30


OVERLAPPING = """
[simulation]
duration = 1e-3
[domain]
upper = [0.02, 0.02, 0.02]
[particles]
density = 2500.0
radius = { distribution = "fixed", value = 1e-3 }
placement = { method = "file", path = "two.csv" }
[contact]
model = "linear"
normal_stiffness = 1.0e5
restitution = 0.5
"""
