"""Kernels compiled in a helper process while this one compiles others, on an empty cache.

A dry scene's first run waited 23-26 s for Numba to compile its kernels, one after the other:
Numba compiles one at a time in a process. Where the cache does not hold the pair sweep yet and
a core is spare, `start` hands the neighbour build (first: the run needs it next), the
kick-drift, the kick and the plane walls' contacts (and on several threads the dry compiled
loop's parallel region of a step's end, kernels/steps.py chunk_steps_end) to `python -m
sphere_cli.compile_ahead`, which compiles them into the same cache, while this process compiles
the pair sweep; `finish` waits for the helper's line saying those are done before the first
forces, and the run loads its kernels from the cache. A fluid's own grid step compiles at its
first fluid step (about 25 s of a cold Navier-Stokes run, 10 s of a Darcy run): where those
kernels are not cached either, the helper then takes one step of a copy of the grid alone
(FluidModule.grid_step_rehearsal) while the run compiles the porosity, the drag and its
compiled steps, and goes on after `finish`; the run waits for a kernel the helper is compiling
(compile_lock.py) and loads it. The helper compiles the code the run would, so results do not
change; a helper that fails leaves the compiles to the run, as before, and one still compiling
when the run's process ends is stopped. Only a new run (not a resumed one) on the CPU and one
rank does this, whether its steps run in the compiled loop or through the hooks:
docs/performance.md, "Compiled in two processes".
"""

from __future__ import annotations

import atexit
import importlib
import os
import pickle
import select
import subprocess
import sys
from pathlib import Path

from . import runtime

# the most a run waits for its helper's DEM kernels [s] (about 10 s on this project's machine)
WAIT_SECONDS = 300.0
# what the helper writes on its standard output once the DEM kernels are in the cache
DONE = b"."


def _cold(dispatcher) -> bool:
    """True if Numba's cache holds no compiled version of this kernel for its source now."""
    try:
        return not dispatcher._cache._cache_file._load_index()
    except Exception:  # noqa: BLE001 - a Numba without this layout: treat the cache as filled
        return False


def _named(dispatcher) -> tuple[str, str]:
    """(module, attribute) by which the helper imports `dispatcher` (a serial twin shares its
    kernel's Python function name, so the attribute is looked up, not taken from it)."""
    module = dispatcher.py_func.__module__
    for name, value in vars(importlib.import_module(module)).items():
        if value is dispatcher:
            return module, name
    raise LookupError(f"{dispatcher} is not an attribute of {module}")


def _signature(kernel, arguments: tuple) -> tuple:
    """The signature a call of `kernel` with `arguments` compiles."""
    return tuple(kernel.typeof_pyval(a) for a in arguments)


def helper_jobs(scene) -> list[tuple]:
    """(kernel, example arguments) of the kernels the helper compiles: the neighbour build, the
    kick-drift, the kick and the plane walls' contacts, those the scene's step calls; on several
    threads, where the steps run in the dry compiled loop, also its one parallel region of a
    step's end (kernels/steps.py chunk_steps_end, about 10 s), which the loop's compile then
    loads."""
    from .kernels.motion import kick, kick_drift, kick_drift_serial, kick_serial
    from .kernels.neighbors import build_lists
    from .kernels.serial import use_serial
    from .kernels.steps import chunk_steps_end
    from .kernels.walls import wall_forces, wall_forces_serial
    from .physics.compiled_steps import CompiledSteps
    from .physics.motion import Motion

    state = scene.state
    serial = use_serial()
    jobs = [
        (build_lists, scene.neighbors.list_arguments(state)),
        (kick_drift_serial if serial else kick_drift, (*Motion.drift_arguments(state), False)),
        (kick_serial if serial else kick, Motion.kick_arguments(state)),
    ]
    walls = None if scene.walls is None else scene.walls.argument_example(state)
    if walls is not None:
        jobs.append((wall_forces_serial if serial else wall_forces, walls))
    loop = scene.step.compiled
    if not serial and type(loop) is CompiledSteps and loop.extra is None and loop.fluid is None:
        cross, pairs = scene.contact.kernel_arguments(state)
        if cross is not None:  # several chunks (CompiledSteps.run: the walls cut at them, same types)
            jobs.append((chunk_steps_end, (pairs, walls, Motion.drift_arguments(state))))
    return jobs


def own_jobs(scene) -> list[tuple]:
    """(kernel, arguments) of the pair sweep, which this process compiles meanwhile: the one the
    step calls (on one thread its serial twin; the parallel sweep, 11 s of compiling, would
    never run)."""
    from .kernels.contact import chunk_pair_forces, chunk_pair_forces_serial, cross_chunk_pairs
    from .kernels.serial import use_serial

    cross, pairs = scene.contact.kernel_arguments(scene.state)
    jobs = [] if cross is None else [(cross_chunk_pairs, cross)]
    return [*jobs, (chunk_pair_forces_serial if use_serial() else chunk_pair_forces, pairs)]


def spare_core(busy: float | None, cores: int) -> bool:
    """True if a core is free for the helper besides this process (`busy`: the cores other
    processes keep busy, None where unknown)."""
    return busy is not None and cores - busy >= 2 - runtime.MARGIN_CORES


def fluid_rehearsal(scene) -> tuple | None:
    """(one of its kernels, function, arguments, threads) of the fluid grid's rehearsal
    (FluidModule.grid_step_rehearsal) on the threads of its own step; None without one."""
    import numba

    fluid = scene.fluid
    rehearsal = None if fluid is None else fluid.grid_step_rehearsal()
    if rehearsal is None:
        return None
    return (*rehearsal, fluid.step_threads or numba.get_num_threads())


def start(scene, busy: float | None = None) -> subprocess.Popen | None:
    """Start the helper for this scene's kernels and compile the pair sweep here (module
    docstring); None where the cache already has the pair sweep and the fluid grid's step, no
    core is spare (`busy`: the busy cores, measured when not given), or the steps are not the
    one-rank CPU steps (those of physics/compiled_steps.py, or the hooks)."""
    from .physics.compiled_steps import CompiledSteps

    compiled = scene.step.compiled
    if compiled is not None and type(compiled) is not CompiledSteps:
        return None  # on ranks or a GPU
    own = [] if scene.contact is None else own_jobs(scene)
    if own and not _cold(own[-1][0]):
        own = []
    fluid = fluid_rehearsal(scene)
    if fluid is not None and not _cold(fluid[0]):
        fluid = None
    if not own and fluid is None:
        return None
    if not spare_core(runtime.measure_busy_cores() if busy is None else busy, runtime.usable_cores()):
        return None
    jobs = [(*_named(k), _signature(k, arguments)) for k, arguments in helper_jobs(scene)] if own else []
    helper = launch(jobs, None if fluid is None else fluid[1:])
    if helper is None:
        return None
    try:
        for kernel, arguments in own:
            kernel.compile(_signature(kernel, arguments))
    except BaseException:
        stop(helper)
        raise
    return helper


def launch(jobs: list[tuple], fluid: tuple | None) -> subprocess.Popen | None:
    """The helper process, given the (module, attribute, signature) of its DEM kernels and the
    (function, arguments, threads) of a fluid rehearsal; stopped when this process ends. None
    where it cannot start."""
    try:
        # the helper imports this very package, wherever this process found it
        found = str(Path(__file__).resolve().parents[1])
        path = os.pathsep.join(filter(None, (found, os.environ.get("PYTHONPATH"))))
        helper = subprocess.Popen(
            [sys.executable, "-m", "sphere_cli.compile_ahead"],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            stderr=subprocess.DEVNULL,
            env={**os.environ, "PYTHONPATH": path},
        )
        atexit.register(stop, helper)
        helper.stdin.write(pickle.dumps((jobs, fluid)))
        helper.stdin.close()
    except OSError:
        return None
    return helper


def finish(helper: subprocess.Popen | None) -> None:
    """Wait until the helper has compiled the DEM kernels (its line on stdout, or its end), or
    stop it after WAIT_SECONDS (the run then compiles the rest). A fluid rehearsal goes on."""
    if helper is None:
        return
    ready, _, _ = select.select([helper.stdout], [], [], WAIT_SECONDS)
    if not ready:
        stop(helper)
        return
    helper.stdout.read(len(DONE))  # the line, or nothing where the helper has ended


def stop(helper: subprocess.Popen | None) -> None:
    """End the helper now (Numba writes each cache file whole, under a temporary name first, so
    a kernel it had not finished is simply not in the cache)."""
    if helper is not None:
        helper.kill()
        helper.wait()
        if helper.stdout is not None:
            helper.stdout.close()


def main() -> int:
    """The helper: compile each (module, attribute, signature) read from stdin (pickled), say
    so on stdout, then take the fluid grid's rehearsal, if any, on its threads."""
    jobs, fluid = pickle.load(sys.stdin.buffer)
    for module, name, signature in jobs:
        getattr(importlib.import_module(module), name).compile(signature)
    sys.stdout.buffer.write(DONE)
    sys.stdout.buffer.flush()
    if fluid is not None:
        import numba

        function, arguments, threads = fluid
        numba.set_num_threads(min(threads, numba.config.NUMBA_NUM_THREADS))
        function(*arguments)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
