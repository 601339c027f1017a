"""Every CLI command as a plain library function (tests and notebooks need no CLI)."""

from __future__ import annotations

import dataclasses
import shutil
import sys
import time as wallclock
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from . import KERNEL_CACHE_NOTE, compile_lock, ranks
from .config.load import LoadedCase, load_case, parse_case, physics_hash, resolved_dict, run_record
from .config.schema import NON_PHYSICS_KEYS, Case
from .errors import (
    MissingInputError,
    NumericalError,
    OutputError,
    ResumeRefused,
    SphereError,
    StoppedEarly,
)
from .io.atomic import write_text_atomic
from .io.checkpoint import list_checkpoints, newest_valid_checkpoint, remove_stale_temporaries
from .io.json_text import json_text
from .io.progress import Progress
from .io.provenance import provenance
from .io.rundir import RunDirectory, RunOutput
from .io.trajectory import TrajectoryBusy, TrajectoryLost
from .runtime import (
    StopFlag,
    refuse_many_ranks,
    set_threads,
    signal_handlers,
    start_threads,
    threads_restored,
)
from .scene.builder import build_scene
from .scene.packing import placed_count
from .simulation import Loop


@dataclass
class RunResult:
    run_dir: Path
    status: str  # "done" (a stop raises StoppedEarly)
    step: int
    time: float
    wall_seconds: float  # from the command's start: the scene's build (and its compiles) included
    particle_steps_per_second: float
    steps_per_second: float = 0.0  # the rate of a scene without particles
    compiling_seconds: float = 0.0  # of wall_seconds, those spent compiling kernels (compile_lock.py)


def _began() -> tuple[float, float]:
    """(wall clock, seconds compiled so far) at a command's start: its summary counts the scene's
    build, whose kernels (the pair sweep, a compiled loop's) take most of a first run's time."""
    return wallclock.monotonic(), compile_lock.seconds_compiling()


def validate(path: str | Path) -> dict:
    """Validate a case file as `run` would before its first step: the placement (a lattice's
    capacity, a placement file's contents) and the time step against the limits of the
    particles, walls and fluid as built (no kernel compiled); returns the resolved case."""
    from .scene.builder import check_build

    loaded = load_case(path)
    check_build(loaded)
    return resolved_dict(loaded.case)


def schema() -> dict:
    return Case.model_json_schema()


def _log_note(log, note: str | None) -> None:
    if note is not None:
        log.warning("%s", note)


def _warn(log, note: str | None) -> None:
    """A warning for run.log and the terminal (the run's logger writes to run.log alone)."""
    if note is not None:
        log.warning("%s", note)
        print(f"sphere: warning: {note}", file=sys.stderr)


def _with_simulation(loaded: LoadedCase, **given) -> LoadedCase:
    """The case with the [simulation] keys given on the command line (None: not given)."""
    update = {key: value for key, value in given.items() if value is not None}
    if not update:
        return loaded
    sim = loaded.case.simulation.model_copy(update=update)
    return LoadedCase(
        case=loaded.case.model_copy(update={"simulation": sim}),
        text=loaded.text,
        path=loaded.path,
        origin=loaded.origin,
    )


def _drive(
    scene,
    rundir: RunDirectory,
    output: RunOutput,
    log,
    max_wall_time: float | None,
    handle_signals: bool,
    show_progress: bool,
    began: tuple[float, float],
) -> RunResult:
    clock = scene.state.clock
    end_step = clock.steps_in(scene.case.simulation.duration)
    start_step = clock.step
    progress = Progress(
        rundir,
        end_step,
        start_step,
        clock.dt,
        scene.state.particles.count,
        scene.case.output.status_every_seconds,
        enabled=show_progress,
    )
    stop = StopFlag()
    loop = Loop(scene, end_step, output, stop, max_wall_time, progress)
    log.info(
        "running from step %d to %d (dt = %.6g s, %d particles)",
        start_step,
        end_step,
        clock.dt,
        scene.state.particles.count,
    )
    if end_step < start_step:  # `resume --until` earlier than where the run is: said, not silent
        _warn(
            log,
            f"the end asked for, t = {scene.case.simulation.duration:.6g} s (step {end_step}), is before "
            f"where the run is, t = {clock.time:.6g} s (step {start_step}): nothing is stepped; give a "
            "later --until",
        )
    _warn(log, _disk_note(rundir, output, scene, loop.frames.every_steps, end_step - start_step))
    log.info("threads: %s", _threads_line(scene))
    gpu = getattr(scene.step.compiled, "device_name", None)
    if gpu is not None:
        log.info("steps on the GPU (simulation.device = cuda): %s", gpu)
        if scene.fluid is not None:
            log.info(
                "fluid: its action on the particles on the GPU every step, its own step every %d steps: %s",
                scene.fluid.coupling_steps,
                scene.fluid.own_step_where,
            )
    if hasattr(scene.step.compiled, "world"):
        log.info("steps %s", scene.step.compiled.describe())
    log.info("time step limit %.6g s: %s", scene.dt_limit, scene.dt_limit_reason)
    log.info("stability bound %.6g s: %s", scene.dt_bound, scene.dt_bound_reason)
    if scene.fluid is not None:
        log.info("fluid: %s", ", ".join(f"{k} {v}" for k, v in scene.fluid.summary().items()))
    try:
        with signal_handlers(stop, handle_signals):
            outcome = loop.run()
        wall = wallclock.monotonic() - began[0]
        # the first step's compilation left out
        steps_rate = progress.rate(clock.step)
        rate = steps_rate * scene.state.particles.count
        if outcome != "done":
            log.warning("stopped early (%s) at step %d; checkpoint written", outcome, clock.step)
            raise StoppedEarly(
                reason=outcome,
                message=f"stopped early ({outcome}) at t = {clock.time:.6g} s (step {clock.step}); a "
                f"checkpoint was written: continue with `sphere resume {rundir.path}`",
            )
        compiling = compile_lock.seconds_compiling() - began[1]
        timed = f"{steps_rate:.3g} steps/s, {rate:.3g} particle-steps/s (compiling left out)"
        log.info(
            "done at step %d (t = %.6g s) in %.1f s, %.1f s of it compiling kernels; %s",
            clock.step, clock.time, wall, compiling, timed if steps_rate > 0.0 else "too few steps to time",
        )  # fmt: skip
        return RunResult(rundir.path, "done", clock.step, clock.time, wall, rate, steps_rate, compiling)
    except NumericalError as exc:
        log.error("%s", exc)
        _record_failure(rundir, clock, str(exc), exc.exit_code)
        output.close(scene)
        raise
    except KeyboardInterrupt:
        log.warning("interrupted at step %d; resume starts from the newest checkpoint", clock.step)
        output.close(scene)
        raise
    except StoppedEarly:  # status.json says "stopped" already
        raise
    except SphereError as exc:  # its files cannot be written (a full disk), an error of the case
        log.error("%s", exc)
        _record_failure(rundir, clock, str(exc), exc.exit_code)
        raise
    except Exception as exc:
        _record_internal_error(exc, scene, rundir, output, log)
        raise
    finally:
        progress.close()
        rundir.close_logger()


def _disk_note(
    rundir: RunDirectory, output: RunOutput, scene, every_steps: int | None, steps: int
) -> str | None:
    """A warning where the frames still to write will not fit the run directory's file system as
    it is now (a frame schedule meant in ms given in us, a file system nearly full): said at the
    start, not found hours later when the run stops on a full disk (exit 74)."""
    if every_steps is None or steps <= 0:
        return None
    frames = steps // every_steps + 1
    need = frames * output.trajectory.frame_bytes(scene)
    try:
        free = shutil.disk_usage(rundir.path).free
    except OSError:
        return None
    if need <= free:
        return None
    return (
        f"the {frames} frames still to write (output.frames: every {every_steps} steps) take about "
        f"{_size(need)} and {rundir.path}'s file system has {_size(free)} free: the "
        "run will stop when it is full (exit 74, its checkpoints kept); fewer frames (output.frames) "
        "or fields (output.fields), or more room, let it finish"
    )


def _size(nbytes: float) -> str:
    for unit in ("B", "KiB", "MiB", "GiB"):
        if nbytes < 1024.0:
            return f"{nbytes:.3g} {unit}"
        nbytes /= 1024.0
    return f"{nbytes:.3g} TiB"


def _record_failure(rundir: RunDirectory, clock, error: str, exit_code: int | None = None) -> None:
    """status.json says "failed", with the error, the step reached and the exit code (74, its
    files could not be written, tells a sweep to resume it), so that a batch job's monitor does
    not see "running" for ever. Best effort: on a full disk it may not be written either (the
    error is on stderr and, where it fits, in run.log)."""
    status = {"state": "failed", "step": clock.step, "time": clock.time, "error": error}
    if exit_code is not None:
        status["exit_code"] = exit_code
    try:
        rundir.write_status(status)
    except OutputError:
        pass


def _record_internal_error(exc: Exception, scene, rundir: RunDirectory, output: RunOutput, log) -> None:
    """A fault of the program, not of the case, during the steps: its traceback goes to run.log
    and status.json says "failed" (a batch job's monitor would otherwise see "running" for ever);
    the frames written so far are closed as at any other stop. Best effort: the exception itself
    is raised on whatever happens here."""
    clock = scene.state.clock
    error = f"internal error at step {clock.step}: {type(exc).__name__}: {exc}"
    log.exception("%s (a bug: please report it with this log)", error)
    _record_failure(rundir, clock, error)
    try:
        output.close(scene)
    except Exception as late:
        log.error("while recording it: %s: %s", type(late).__name__, late)


def _placed(loaded: LoadedCase) -> int | None:
    """The particles of a case that places them from a file (its count sizes the run's threads),
    else None (the case says, or there is no such file)."""
    placement = loaded.case.particles.placement
    if loaded.case.particles.count is not None or getattr(placement, "method", None) != "file":
        return None
    return placed_count(placement, loaded.base_dir)


def _threads_line(scene) -> str:
    """The threads the run's parallel kernels take (runtime.run_threads, grid_threads)."""
    import numba

    line = f"{numba.get_num_threads()} for the particles' kernels"
    grid = getattr(scene.fluid, "step_threads", None)
    if grid is not None:
        line += f", {grid} for the fluid grid's own step (by its cells)"
    return line


def run(
    case_path: str | Path,
    run_dir: str | Path | None = None,
    overwrite: bool = False,
    max_wall_time: float | None = None,
    handle_signals: bool = False,
    show_progress: bool = False,
    until: float | None = None,
    origin: str | Path | None = None,
    device: str | None = None,
) -> RunResult:
    """Run a case in a new run directory. `origin`: the case file whose folder resolves the
    case's relative paths, if not the case's own (a sweep member's: sphere_cli/sweep.py)."""
    began = _began()
    refuse_many_ranks(joined=ranks.current() is not None)
    loaded = _with_simulation(load_case(case_path), duration=until, device=device)
    if origin is not None:
        loaded = dataclasses.replace(loaded, origin=Path(origin))
    rundir = RunDirectory(Path(run_dir) if run_dir is not None else Path("runs") / Path(case_path).stem)
    rundir.check_new(overwrite)
    with threads_restored():
        note = start_threads(loaded.case, _placed(loaded))
        try:
            # the directory and status.json exist from the start: a batch job's monitor sees the run
            # while its first scene compiles the kernels (a minute or more on a machine's first run)
            rundir.prepare_new(overwrite, loaded.text, Path(origin if origin is not None else case_path))
            try:
                log = rundir.logger()
                log.info("case %s -> %s", case_path, rundir.path)
                _starting(rundir, show_progress)
                scene = build_scene(loaded)
            except BaseException:
                rundir.discard_new()  # a case refused while building leaves nothing behind
                raise
            try:
                if rundir.replaced is not None:
                    log.info("the run replaced is kept at %s until the first checkpoint", rundir.replaced)
                _log_note(log, note)
                output = start_output(scene, rundir, loaded, log)
            except BaseException:
                rundir.abandon_new()
                raise
            return _drive(scene, rundir, output, log, max_wall_time, handle_signals, show_progress, began)
        finally:
            rundir.close_logger()
            rundir.unlock()


def _starting(rundir: RunDirectory, show_progress: bool) -> None:
    """status.json and the terminal say what happens before the first step; on several ranks,
    each learns where to record an error that aborts them all."""
    rundir.write_starting()
    _warn(rundir.logger(), KERNEL_CACHE_NOTE)  # kernels cached where they may not last
    _warn(rundir.logger(), rundir.lock_note)  # a file system that cannot lock
    world = ranks.current()
    if world is not None:
        world.record_failures_in(rundir.path.resolve())
    if show_progress:
        print(
            "[sphere] building the scene and compiling the kernels (cached after a first run) ...",
            file=sys.stderr,
            flush=True,
        )


def start_output(scene, rundir: RunDirectory, loaded: LoadedCase, log) -> RunOutput:
    """A new trajectory with the starting frame, and the first checkpoint (from then on the run
    can be resumed)."""
    resolved = run_record(loaded)
    phash = physics_hash(resolved)
    output = RunOutput(rundir, scene, loaded.text, resolved, phash, log)
    output.trajectory.create(scene, loaded.text, resolved, phash, provenance())
    output.first(scene)
    output.checkpoint(scene)
    return output


def resume(
    run_dir: str | Path,
    until: float | None = None,
    max_wall_time: float | None = None,
    handle_signals: bool = False,
    show_progress: bool = False,
    device: str | None = None,
) -> RunResult:
    refuse_many_ranks(joined=ranks.current() is not None)
    rundir = RunDirectory(Path(run_dir))
    if not rundir.is_run():
        raise MissingInputError(rundir.why_not_run())
    rundir.lock()
    try:
        with threads_restored():
            return _resume_locked(rundir, until, max_wall_time, handle_signals, show_progress, device)
    finally:
        rundir.close_logger()
        rundir.unlock()


def _resume_locked(
    rundir: RunDirectory, until, max_wall_time, handle_signals, show_progress, device
) -> RunResult:
    began = _began()
    loaded = dataclasses.replace(load_case(rundir.case), origin=rundir.case_origin())
    loaded = _with_simulation(loaded, duration=until, device=device)
    if rundir.xdmf.exists() and not rundir.xdmf.is_file():
        raise OutputError(f"{rundir.xdmf}: is not a file; remove or rename it, then resume again")
    remove_stale_temporaries(rundir.checkpoints)
    log = rundir.logger()
    ck = newest_valid_checkpoint(rundir.checkpoints, log=log.warning)
    if ck is None and not list_checkpoints(rundir.checkpoints):
        _refuse_lost_checkpoints(rundir, log)
        # stopped before its first checkpoint: nothing was computed that a new start would not redo
        log.warning("no checkpoint yet (stopped before the first one): starting again from step 0")
        fresh = parse_case(loaded.text, rundir.case_origin() or rundir.case)
        fresh = _with_simulation(fresh, duration=until, device=device)
        note = start_threads(fresh.case, _placed(fresh))
        with _status_kept_unless_started(rundir, log):
            _starting(rundir, show_progress)
            scene = build_scene(fresh)
            _log_note(log, note)
            output = start_output(scene, rundir, fresh, log)
        return _drive(scene, rundir, output, log, max_wall_time, handle_signals, show_progress, began)
    if ck is None:
        raise MissingInputError(f"{rundir.checkpoints}: no checkpoint that verifies; cannot resume")
    rundir.checkpoint = ck.path.name
    if device is None:  # the device the run was on (a --device given to sphere run is not in case.toml)
        loaded = _with_simulation(loaded, device=ck.resolved.get("simulation", {}).get("device"))
    resolved = run_record(loaded)
    phash = physics_hash(resolved)
    if phash != ck.physics_hash:
        changed = ", ".join(_changed_keys(ck.resolved, resolved)) or "(unknown)"
        raise ResumeRefused(
            f"{rundir.case}: changed in a way that alters the physics since {ck.path.name} was written "
            f"(changed: {changed}); only {', '.join('.'.join(k) for k in NON_PHYSICS_KEYS)} may "
            "change on resume. Start a new run instead."
        )
    old_fields = ck.resolved["output"]["fields"]
    if loaded.case.output.fields != old_fields:
        raise ResumeRefused(
            f"{rundir.case}: output.fields changed from {old_fields} to {loaded.case.output.fields}; "
            "the trajectory file holds the original fields. Restore them, or start a new run."
        )
    note = start_threads(loaded.case, _placed(loaded))
    with _status_kept_unless_started(rundir, log):
        _starting(rundir, show_progress)
        scene = build_scene(loaded, restart=ck)
        log.info("resuming from %s (step %d)", ck.path.name, ck.step)
        _log_note(log, note)
        output = RunOutput(rundir, scene, loaded.text, resolved, phash, log)
        output.last_checkpoint = ck.path
        try:
            output.trajectory.truncate_after(ck.step)
        except OutputError as exc:
            if isinstance(exc, TrajectoryBusy):  # not damaged: another program has it open to write
                raise
            if not isinstance(exc, TrajectoryLost):
                aside = rundir.trajectory_path.with_name(f"trajectory.unreadable-{int(wallclock.time())}.h5")
                rundir.trajectory_path.rename(aside)
                exc = f"{exc}; moved it to {aside.name}"
            log.warning("%s: a new trajectory file starts at %s", exc, ck.path.name)
            output.trajectory.create(scene, loaded.text, resolved, phash, provenance())
            output.first(scene)
        output.trajectory.record_resume(ck.step, provenance())
    return _drive(scene, rundir, output, log, max_wall_time, handle_signals, show_progress, began)


def _refuse_lost_checkpoints(rundir: RunDirectory, log) -> None:
    """A run whose checkpoints are gone after it wrote some (deleted to free space, a scratch
    purge) is not resumed from step 0: that would rewrite its trajectory, whose frames may be
    all that is left of days of running, from the start. status.json names the newest checkpoint
    written (absent: the run stopped before its first, and starts again)."""
    written = rundir.read_status().get("checkpoint")
    if written is None:
        return
    message = (
        f"{rundir.checkpoints}: holds no checkpoint, but the run wrote {written} (status.json); a resume "
        f"would start again from step 0 and rewrite {rundir.trajectory_path.name}. Put the checkpoints "
        f"back, or start the run again: sphere run CASE -o {rundir.path} --overwrite"
    )
    log.error("%s", message)
    raise MissingInputError(message)


@contextmanager
def _status_kept_unless_started(rundir: RunDirectory, log):
    """A resume that stops before its first step (a device that cannot be used, a file the case
    reads gone, Ctrl-C while it compiles) changed nothing of the run: status.json gets back what
    it said before ("done", "stopped", ...) instead of staying "starting" for good, and run.log
    says why the resume did not start. Best effort: the error is on stderr."""
    try:
        before = rundir.status_path.read_text(encoding="utf-8")
    except OSError:
        before = None
    try:
        yield
    except BaseException as exc:
        if isinstance(exc, SphereError):
            log.error("the resume stopped before its first step: %s", exc)
        if before is not None:
            try:
                write_text_atomic(rundir.status_path, before)
            except OSError:
                pass
        raise


def _changed_keys(old, new, prefix: str = "") -> list[str]:
    keys = []
    if isinstance(old, dict) and isinstance(new, dict):
        for key in sorted(set(old) | set(new)):
            keys += _changed_keys(old.get(key), new.get(key), f"{prefix}{key}.")
    elif old != new:
        keys.append(prefix.rstrip("."))
    free = tuple(".".join(key) for key in NON_PHYSICS_KEYS)
    return [k for k in keys if not k.startswith(free)]


def run_in_memory(text: str, steps: int, base_dir: Path | None = None):
    """Build a scene from TOML text and advance it `steps` steps (tests, notebooks), on the
    threads of its `simulation.threads` if it sets them (for this process from then on: the
    scene it returns steps on them), else on the process's, its fluid grid's step too (which
    `run` sizes by the grid: runtime.grid_threads). (`run` and `resume` give the process its
    thread count back when they end.)"""
    from .simulation import advance

    loaded = parse_case(text, None if base_dir is None else base_dir / "case.toml")
    if loaded.case.simulation.threads is not None:
        set_threads(loaded.case)
    scene = build_scene(loaded)
    if scene.fluid is not None:
        scene.fluid.step_threads = None
    advance(scene, steps)
    return scene


def inspect(path: str | Path) -> dict:
    from .io.inspect import summarize

    return summarize(Path(path))


def plot(run_dir: str | Path, out_dir: str | Path | None = None) -> list[Path]:
    """PNG figures of a run's observables (sphere_cli/io/plot.py); returns the files written."""
    from .io.plot import plot_run

    return plot_run(run_dir, out_dir)


def to_json(data) -> str:
    """Strict JSON (io/json_text.py: a value NaN or infinite is null)."""
    return json_text(data)
