"""Kernels compiled ahead in a helper process on an empty cache (sphere_cli/compile_ahead.py): the
helper compiles exactly what the run then loads instead of compiling it, and nothing starts where
the cache already holds the kernels or no core is spare."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numba
import pytest

from sphere_cli import compile_ahead
from sphere_cli.bench.dem import canonical_case
from sphere_cli.config.load import load_case, parse_case
from sphere_cli.errors import SphereError
from sphere_cli.scene.builder import build_scene
from sphere_cli.simulation import advance

CONFIGS = Path(__file__).resolve().parents[2] / "configs"


@pytest.mark.parametrize("n", [64, 256])  # the serial twins below 200 particles on one thread
def test_the_jobs_are_the_kernels_the_run_compiles(n):
    """Each job's kernel is compiled for the signature its arguments give when the steps call it
    (chunk_steps_end, which only the compiled loop calls, has a test of its own below)."""
    from sphere_cli.kernels.steps import chunk_steps_end

    scene = build_scene(parse_case(canonical_case(n)))
    jobs = compile_ahead.helper_jobs(scene) + compile_ahead.own_jobs(scene)
    jobs = [(kernel, arguments) for kernel, arguments in jobs if kernel is not chunk_steps_end]
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


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="one thread runs the serial loop")
@pytest.mark.parametrize("walls", [True, False])
def test_on_several_threads_the_helper_compiles_the_loops_region_for_the_runs_arguments(monkeypatch, walls):
    """On two threads the helper also compiles kernels/steps.py chunk_steps_end, which the dry
    compiled loop calls: with the types of the pairs, the walls cut at the chunks (or None) and
    the kick-drift's arguments that CompiledSteps.run gives the loop (else the loop's compile
    would not find it in the cache and compile it again). The loop itself is replaced by one
    that keeps its arguments, the helper by the jobs it would be given."""
    from sphere_cli.kernels.steps import chunk_steps_end
    from sphere_cli.physics import compiled_steps
    from sphere_cli.runtime import threads_set_to

    text = canonical_case(256)
    if not walls:  # no wall: a box periodic on every axis
        for face in ("x-", "x+", "y-", "y+", "z-", "z+"):
            text = text.replace(f'[[walls]]\nface = "{face}"\n', "")
        text = text.replace("[domain]\n", "[domain]\nperiodic = [true, true, true]\n")
        assert "[[walls]]" not in text and "periodic" in text
    calls = []

    def loop(*arguments):
        calls.append(arguments)
        return 0, 0.0, False

    seen = []  # the helper's jobs as the scene's build hands them out, before the list is built
    monkeypatch.setattr(compile_ahead, "start", lambda scene: seen.extend(compile_ahead.helper_jobs(scene)))
    with threads_set_to(2):
        scene = build_scene(parse_case(text))
        jobs = [arguments for kernel, arguments in seen if kernel is chunk_steps_end]
        monkeypatch.setattr(compiled_steps, "dem_steps", loop)
        scene.step.compiled.run(scene.state, 5)
    assert len(jobs) == 1 and len(calls) == 1
    drift, pairs, chunked = calls[0][2], calls[0][4], calls[0][10]
    assert (chunked is not None) == walls
    signature = compile_ahead._signature(chunk_steps_end, jobs[0])
    assert signature == compile_ahead._signature(chunk_steps_end, (pairs, chunked, drift))
    with threads_set_to(1):  # one thread: the serial loop, no region to compile
        assert chunk_steps_end not in [kernel for kernel, _ in compile_ahead.helper_jobs(scene)]


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
helper is None or helper.wait(timeout=60)  # a dry scene's helper ends with its DEM kernels
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
    assert report["started"] and report["helper_exit"] == 0, report
    # each of the helper's kernels came from the cache here, the pair sweep was compiled here
    assert set(report["loaded"]) == {"build_lists", "kick_drift", "kick", "wall_forces_serial"}
    assert all(hits == 1 for hits in report["loaded"].values()), report
    assert report["compiled"] == {"chunk_pair_forces_serial": 1}


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


# a fluid's grid step rehearsed in this process (FluidModule.grid_step_rehearsal, as the helper
# takes it), then the run's own first fluid steps: which kernels of the grid's step they call
# with a signature the rehearsal did not compile (the cache is warm here, so each process loads
# rather than compiles; the signatures are what matters)
REHEARSED = """
import json, sys
import numpy as np
from numba.core.dispatcher import Dispatcher
from sphere_cli import compile_ahead
from sphere_cli.config.load import parse_case
from sphere_cli.runtime import threads_set_to
from sphere_cli.scene.builder import build_scene
from sphere_cli.simulation import advance

GRID_STEP = ("navier_stokes", "poisson", "pore_pressure")
compile_ahead.start = lambda scene: None

def signatures():
    found = set()
    for name, module in list(sys.modules.items()):
        if name.startswith("sphere_cli.kernels.fluid.") and name.rsplit(".", 1)[1] in GRID_STEP:
            for attribute, value in vars(module).items():
                if isinstance(value, Dispatcher):
                    found |= {(name, attribute, str(s)) for s in value.signatures}
    return found

report = []
for text in json.loads(sys.stdin.read()):
    scene = build_scene(parse_case(text))
    kernel, function, arguments, threads = compile_ahead.fluid_rehearsal(scene)
    spacing = scene.fluid.grid().spacing.copy()
    before = signatures()
    with threads_set_to(threads):
        function(*arguments)
    rehearsed = signatures()
    unchanged = bool(np.array_equal(spacing, scene.fluid.grid().spacing))
    advance(scene, 2 * scene.fluid.coupling_steps + 1)
    missed = sorted(map(list, signatures() - rehearsed))
    report.append({"compiled": len(rehearsed - before), "missed": missed, "grid_unchanged": unchanged,
                   "kernel": kernel.py_func.__name__})
print(json.dumps(report))
"""


def _with_top_wall(text: str, cells: str) -> str:
    """The case with a top wall coming down slowly and the fluid grid following it."""
    wall = '[[walls]]\nface = "z+"\nmode = "velocity"\nvelocity = 0.01\n'
    assert text.count("[fluid]\n") == 1 and text.count(cells) == 1
    grid = cells.replace("] }", "], follow_top_wall = true }")
    return text.replace("[fluid]\n", wall + "[fluid]\n").replace(cells, grid)


@pytest.mark.parametrize(
    ("config", "cells"),
    [
        ("fluid-settling.toml", "grid = { cells = [5, 5, 10] }"),
        ("seepage-pulses-darcy.toml", "grid = { cells = [4, 4, 12] }"),
    ],
)
def test_the_fluid_grid_rehearsal_compiles_what_its_step_calls(config, cells):
    """What the helper compiles for a fluid (its grid's step alone, without the particles) is every
    kernel of the grid's step the run then calls, with the same signatures: on a fixed grid, then
    (kernels of its own) on one following the top wall; and it leaves the run's grid alone."""
    text = (CONFIGS / config).read_text()
    cases = [text, _with_top_wall(text, cells)]
    done = subprocess.run(
        [sys.executable, "-c", REHEARSED],
        input=json.dumps(cases),
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    fixed, moving = json.loads(done.stdout.strip().splitlines()[-1])
    assert fixed["compiled"] >= 5, fixed  # beyond the pressure gradient that the initial state takes
    for report in (fixed, moving):
        assert report["missed"] == [] and report["grid_unchanged"], report


def test_the_run_goes_on_once_the_helper_has_its_dem_kernels():
    """finish() returns at the helper's line, while a fluid's rehearsal goes on; a helper that
    ends without one is not waited for either."""
    line = "import sys, time; sys.stdout.buffer.write(b'.'); sys.stdout.flush(); time.sleep(120)"
    for script in (line, "pass"):
        helper = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE)
        started = time.perf_counter()
        compile_ahead.finish(helper)
        assert time.perf_counter() - started < 30
        if script == line:
            assert helper.poll() is None
        compile_ahead.stop(helper)
        assert helper.poll() is not None


# a helper launched with a fluid rehearsal that outlasts this process (a minute's sleep)
OUTLIVED = """
import time
from sphere_cli import compile_ahead
helper = compile_ahead.launch([], (time.sleep, (60.0,), 1))
compile_ahead.finish(helper)
print(helper.pid, helper.poll() is None)
"""


def test_a_helper_still_compiling_is_stopped_when_the_run_ends():
    done = subprocess.run([sys.executable, "-c", OUTLIVED], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-3000:]
    pid, running = done.stdout.split()
    assert running == "True"  # still rehearsing when the run's process ended
    with pytest.raises(ProcessLookupError):
        os.kill(int(pid), 0)
