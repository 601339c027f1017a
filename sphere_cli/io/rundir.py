"""The run directory: case copy, trajectory + XDMF, checkpoints, status.json and run.log.

RUN_DIR/.sphere-run        marker: written first, names the directory as sphere's; the lock file
RUN_DIR/case.toml          the case as given (edit non-physics keys here before `resume`)
RUN_DIR/trajectory.h5      frames and observables (H5MD)
RUN_DIR/trajectory.xmf     ParaView sidecar
RUN_DIR/checkpoints/       ckpt-<step>.h5, newest K kept
RUN_DIR/status.json        progress for batch monitoring, rewritten atomically
RUN_DIR/run.log            what happened, appended by every run and resume
RUN_DIR/plots/             the figures of `sphere plot`

One process writes a run directory at a time: `run` and `resume` hold an exclusive lock
(flock) on the marker from start to end, and a second writer is refused (RunBusy). Readers
take no lock. `--overwrite` replaces only a directory that sphere wrote (the marker, and no
file sphere did not write), moves it aside rather than deleting it, and deletes it only once
the new run has published its first checkpoint.
"""

from __future__ import annotations

import errno
import fcntl
import json
import logging
import os
import re
import shutil
import sys
import time
import warnings
from datetime import UTC, datetime
from pathlib import Path

from .. import ranks
from ..errors import OutputError, RunBusy, UsageError
from ..physics.fluid_plugin import MOVING_GRID_SPACING
from .atomic import write_text_atomic
from .checkpoint import NAME as CHECKPOINT_NAME
from .checkpoint import remove_stale_temporaries, write_checkpoint
from .json_text import json_text
from .provenance import provenance
from .trajectory import Trajectory, TrajectoryBusy, TrajectoryLost, frame_clock, is_grid_field, open_as_writer
from .xdmf import frame_grid, write_xdmf

MARKER = ".sphere-run"
# how long `lock` waits for a lock held by someone else before saying the run is in use [s]
LOCK_PATIENCE = 0.2
# what flock(2) answers on a file system that cannot lock (NFS without its lock service, a
# Lustre client mounted without flock): the run goes on without the lock, warned in run.log
NO_LOCKS = {errno.ENOLCK, errno.ENOSYS, errno.EOPNOTSUPP, errno.EINVAL}
# The ParaView sidecar lists every frame and is replaced whole, so rewriting it at each frame
# costs in proportion to the frames so far (quadratic in a run); during a run it is rewritten at
# most this often [s] (wall clock), and always with the run's end frame
XDMF_REFRESH_SECONDS = 2.0
# what sphere writes at the top of a run directory (atomic writes leave ".<name>.tmp" for an instant)
OWN_FILES = re.compile(
    r"^(\.sphere-run|case\.toml|trajectory\.h5|trajectory\.xmf|status\.json|run\.log"
    r"|trajectory\.unreadable-\d+\.h5|\.(sphere-run|case\.toml|trajectory\.xmf|status\.json)\.tmp)$"
)
OWN_FOLDERS = {
    "checkpoints": lambda name: bool(CHECKPOINT_NAME.match(name) or re.match(r"^\.ckpt-\d+\.h5\.tmp$", name)),
    "plots": lambda name: name.endswith(".png"),
}


def _same_file(fd: int, path: Path) -> bool:
    """Whether the open file `fd` is the one at `path` now."""
    try:
        here, there = os.fstat(fd), os.stat(path)
    except OSError:
        return False
    return (here.st_dev, here.st_ino) == (there.st_dev, there.st_ino)


class RunDirectory:
    def __init__(self, path: Path):
        self.path = Path(path)
        self.marker = self.path / MARKER
        self.case = self.path / "case.toml"
        self.trajectory_path = self.path / "trajectory.h5"
        self.xdmf = self.path / "trajectory.xmf"
        self.checkpoints = self.path / "checkpoints"
        self.status_path = self.path / "status.json"
        self.log_path = self.path / "run.log"
        self._lock_fd: int | None = None
        self._trajectory_fd: int | None = None  # the shared lock held on trajectory.h5 (hold_trajectory)
        # the old run moved aside by --overwrite, kept until the new run's first checkpoint
        self.replaced: Path | None = None
        self.created = False  # prepare_new made the directory itself
        # the newest checkpoint written or resumed from, named in status.json (a resume finding
        # checkpoints/ emptied then knows the run had some: api.py _resume_locked)
        self.checkpoint: str | None = None
        self._echo: _WarningsToLog | None = None
        # why the writer lock could not be taken where the file system has no locks (else None)
        self.lock_note: str | None = None

    def is_run(self) -> bool:
        return self.why_not_run() is None

    def why_not_run(self) -> str | None:
        """Why the directory is not a run directory (None if it is): a run's holds its case.toml
        and something only a run writes (its marker, status.json, checkpoints/); a folder of
        the user's that holds a case.toml is not one, and resuming it would write a run there."""
        if not self.case.is_file():
            return f"{self.path}: not a run directory (no case.toml)"
        if not (self.marker.is_file() or self.status_path.is_file() or self.checkpoints.is_dir()):
            return (
                f"{self.path}: not a run directory: it holds a case.toml but nothing a run writes "
                f"({MARKER}, status.json, checkpoints/); give the directory that `sphere run -o` made"
            )
        return None

    def check_new(self, overwrite: bool) -> None:
        """Refuse, before any work, to clobber an existing run unless told to, and to let
        --overwrite touch anything that is not a sphere run."""
        p = self.path
        if p.exists() and not p.is_dir():
            raise OutputError(f"{p}: exists and is not a directory")
        if not (p.is_dir() and any(p.iterdir())) or self.unstarted():
            return
        if not overwrite:
            raise UsageError(
                f"{p}: the run directory exists and is not empty; choose another with -o, "
                "continue it with `sphere resume`, or pass --overwrite to replace it"
            )
        _refuse_special(p)
        marked = self.marker.is_file()
        foreign = self.foreign_entries() if marked else sorted(e.name for e in p.iterdir())
        shown = ", ".join(foreign[:8]) + (f" and {len(foreign) - 8} more" if len(foreign) > 8 else "")
        if not marked:
            raise UsageError(
                f"{p}: --overwrite refused: sphere did not create this directory as a run directory "
                f"(it has no {MARKER} marker) and it holds {shown}; remove it yourself or choose "
                "another with -o"
            )
        if foreign:
            raise UsageError(
                f"{p}: --overwrite refused: the directory holds files sphere did not write ({shown}); "
                "move them elsewhere or choose another run directory with -o"
            )

    def foreign_entries(self) -> list[str]:
        """Entries of the directory that sphere did not write, as paths relative to it."""
        foreign = []
        for entry in sorted(self.path.iterdir()):
            own_folder = OWN_FOLDERS.get(entry.name)
            if own_folder is not None and entry.is_dir() and not entry.is_symlink():
                inside = sorted(e.name for e in entry.iterdir())
                foreign += [f"{entry.name}/{name}" for name in inside if not own_folder(name)]
            elif not (OWN_FILES.match(entry.name) and entry.is_file() and not entry.is_symlink()):
                foreign.append(entry.name + ("/" if entry.is_dir() else ""))
        return foreign

    def unstarted(self) -> bool:
        """Holds only what a start killed before its case.toml was written leaves."""
        return {e.name for e in self.path.iterdir()} <= {MARKER, f".{MARKER}.tmp", ".case.toml.tmp"}

    def prepare_new(self, overwrite: bool, case_text: str, case_path: Path | None = None) -> None:
        """Create the directory: its marker first (locked for this process), then case.toml,
        then checkpoints/, so that a directory with a case.toml can always be resumed. With
        --overwrite the old run is first locked (refused if in use) and moved aside."""
        p = self.path
        self.check_new(overwrite)
        if p.is_dir() and any(p.iterdir()) and not self.unstarted():
            self.lock()
            stamp = datetime.now(UTC).strftime("%Y%m%dT%H%M%S")
            aside = p.with_name(f".{p.name}.replaced-{stamp}-{os.getpid()}")
            try:
                p.rename(aside)
            except OSError as exc:
                raise OutputError(f"{p}: cannot move the old run aside to {aside.name} ({exc})") from None
            self.unlock()
            self.replaced = aside
        try:
            self.created = not p.exists()
            p.mkdir(parents=True, exist_ok=True)
            info = {"sphere_run": 1, "created": datetime.now(UTC).isoformat(timespec="seconds")}
            if case_path is not None:
                info["case"] = str(Path(case_path).resolve())
            # locked before it is written, and written in place: a second process starting the
            # same run at once finds it locked (a marker replaced by rename would give each
            # process a lock of its own, on two files)
            self.lock()
            data = (json.dumps(info) + "\n").encode()
            os.ftruncate(self._lock_fd, 0)
            os.pwrite(self._lock_fd, data, 0)
            os.fsync(self._lock_fd)
            write_text_atomic(self.case, case_text)
            self.checkpoints.mkdir(exist_ok=True)
        except OSError as exc:
            raise OutputError(f"{p}: cannot create the run directory ({exc})") from None
        remove_stale_temporaries(self.checkpoints)

    def checkpoint_written(self, name: str) -> None:
        """A checkpoint of this run exists (status.json names the newest from now on): the new run
        can be resumed on its own, and the old run moved aside is no longer needed."""
        self.checkpoint = name
        if self.replaced is not None:
            shutil.rmtree(self.replaced, ignore_errors=True)
            self.replaced = None

    def abandon_new(self) -> None:
        """The new run failed before its first checkpoint: put the old run back."""
        if self.replaced is None:
            return
        self.close_logger()
        self.unlock()
        shutil.rmtree(self.path, ignore_errors=True)
        self.replaced.rename(self.path)
        self.replaced = None

    def discard_new(self) -> None:
        """The new run was refused while its scene was built (a bad case): leave no trace of it,
        and the old run back where --overwrite had moved it aside."""
        if self.replaced is not None:
            self.abandon_new()
            return
        self.close_logger()
        self.unlock()
        if not self.path.is_dir():
            return
        for entry in self.path.iterdir():  # only what sphere wrote: the directory was empty
            if entry.name in OWN_FOLDERS and entry.is_dir() and not entry.is_symlink():
                shutil.rmtree(entry, ignore_errors=True)
            elif OWN_FILES.match(entry.name):
                entry.unlink(missing_ok=True)
        if self.created:
            try:
                self.path.rmdir()
            except OSError:  # something else appeared in it meanwhile: left as it is
                pass

    def write_starting(self) -> None:
        """status.json while the scene is built and the kernels compiled, before the first step."""
        self.write_status(
            {
                "state": "starting",
                "activity": "building the scene and compiling the kernels (cached after a first run)",
            }
        )

    def _read_marker(self) -> str:
        """The marker's text; through the locked descriptor while this holds the lock (on NFS a
        lock is the process's, and closing any other descriptor of the file would drop it)."""
        if self._lock_fd is None:
            return self.marker.read_text(encoding="utf-8")
        size = os.fstat(self._lock_fd).st_size
        return os.pread(self._lock_fd, size, 0).decode("utf-8")

    def case_origin(self) -> Path | None:
        """The case file the run was started from (its folder resolves relative paths), if known."""
        try:
            origin = json.loads(self._read_marker()).get("case")
        except (OSError, ValueError, AttributeError):
            return None
        return Path(origin) if isinstance(origin, str) else None

    def lock(self) -> None:
        """Take the run directory's exclusive writer lock (RunBusy if another process holds it
        for longer than LOCK_PATIENCE: a reader's probe, `busy`, holds it for microseconds). A
        lock won on a marker that is no longer the directory's (moved aside by `run --overwrite`
        while this waited) is let go and the marker there now tried instead."""
        if self._lock_fd is not None:
            return
        deadline = time.monotonic() + LOCK_PATIENCE
        while True:
            try:
                fd = os.open(self.marker, os.O_RDWR | os.O_CREAT, 0o644)
            except OSError as exc:
                raise OutputError(f"{self.marker}: cannot open the run directory's lock ({exc})") from None
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except OSError as exc:
                if exc.errno in NO_LOCKS:  # the file system cannot lock: run unguarded, and say so
                    self._lock_fd = fd
                    self.lock_note = (
                        f"{self.path}: its file system cannot lock files ({exc.strerror}): nothing keeps "
                        "a second sphere process from writing this run directory at the same time; "
                        "do not start another run or resume on it while this one goes on"
                    )
                    return
                os.close(fd)
                held = exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES)
                if not held:
                    raise OutputError(f"{self.marker}: cannot lock the run directory ({exc})") from None
                if time.monotonic() >= deadline:
                    raise RunBusy(
                        f"{self.path}: another sphere process is writing this run directory (it holds "
                        f"the lock on {MARKER}); wait for it to end, or stop it, before `run --overwrite` "
                        "or `resume`"
                    ) from None
                time.sleep(0.01)
                continue
            if _same_file(fd, self.marker):
                self._lock_fd = fd
                return
            os.close(fd)

    def busy(self) -> bool:
        """Whether some process holds the writer lock now."""
        return self._probe_lock() is True

    def writer_gone(self) -> bool:
        """Whether no process holds the writer lock now (a run that says it is running was
        killed, or its machine went down). A probe that cannot lock at all (a file system
        without locks) says nothing: False."""
        return self._probe_lock() is False

    def _probe_lock(self) -> bool | None:
        """True if another process holds the writer lock, False if none does, None if this
        process holds it, there is none yet, or the file system cannot say. Probed with a
        shared lock (which a read-only open may take, also on NFS) and released at once."""
        if self._lock_fd is not None or not self.marker.is_file():
            return None
        try:
            fd = os.open(self.marker, os.O_RDONLY)
        except OSError:
            return None
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError as exc:
            return True if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES) else None
        finally:
            os.close(fd)  # closing releases a lock taken here
        return False

    def unlock(self) -> None:
        if self._trajectory_fd is not None:
            os.close(self._trajectory_fd)
            self._trajectory_fd = None
        if self._lock_fd is not None:
            os.close(self._lock_fd)  # closing releases the flock
            self._lock_fd = None

    def hold_trajectory(self) -> None:
        """A shared lock on trajectory.h5, as HDF5 takes its locks (flock), held from the run's
        first write to it until unlock(). Readers take the same shared lock (h5py's default,
        ParaView) and open the file as before, but a program opening it to write (h5py's modes
        "r+", "a" and "w": HDF5's exclusive lock) is refused while the run goes on; and a run
        or resume finding it held so stops (TrajectoryBusy) instead of writing beside it: two
        processes writing an HDF5 file corrupt it for good (a notebook's h5py.File(path, "r+"),
        closed after a resume had appended frames, left the whole trajectory unreadable). Taken
        again when the file at the path is another (a trajectory begun anew); nothing is held on
        a file system without locks (run.log says so: `lock`)."""
        if self._trajectory_fd is not None:
            if _same_file(self._trajectory_fd, self.trajectory_path):
                return
            os.close(self._trajectory_fd)
            self._trajectory_fd = None
        try:
            fd = os.open(self.trajectory_path, os.O_RDONLY)
        except OSError:
            return  # the write that follows reports what is wrong with the file
        try:
            fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
        except OSError as exc:
            os.close(fd)
            if exc.errno in NO_LOCKS:
                return
            if exc.errno in (errno.EWOULDBLOCK, errno.EAGAIN, errno.EACCES):
                raise TrajectoryBusy(
                    f'{self.trajectory_path}: open for writing in another program (h5py\'s mode "r+", '
                    '"a" or "w", an HDF5 editor); two programs writing an HDF5 file corrupt it: close it '
                    f'there (reading it, mode "r", is fine), then `sphere resume {self.path}`'
                ) from None
            raise OutputError(f"{self.trajectory_path}: cannot lock the trajectory ({exc})") from None
        self._trajectory_fd = fd

    def logger(self) -> logging.Logger:
        log = logging.getLogger(f"sphere.run.{self.path.resolve()}")
        log.setLevel(logging.INFO)
        log.propagate = False
        if not log.handlers:
            try:
                handler = _LogFile(self.log_path, encoding="utf-8")
            except OSError as exc:
                raise OutputError(f"{self.log_path}: cannot open the log ({exc})") from None
            handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(message)s"))
            log.addHandler(handler)
        if self._echo is None:
            self._echo = _WarningsToLog(log)
        return log

    def close_logger(self) -> None:
        if self._echo is not None:
            self._echo.detach()
            self._echo = None
        log = logging.getLogger(f"sphere.run.{self.path.resolve()}")
        for handler in list(log.handlers):
            handler.close()
            log.removeHandler(handler)

    def read_status(self) -> dict:
        """status.json as written, or {} where it is missing or not a status (damaged)."""
        try:
            status = json.loads(self.status_path.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return {}
        return status if isinstance(status, dict) else {}

    def write_status(self, info: dict) -> None:
        if self.checkpoint is not None:
            info = {**info, "checkpoint": self.checkpoint}
        info = {**info, "ranks": ranks.count(), "updated": datetime.now(UTC).isoformat(timespec="seconds")}
        try:
            write_text_atomic(self.status_path, json_text(info) + "\n")
        except OSError as exc:
            raise OutputError(f"{self.status_path}: cannot write status ({exc})") from None

    def record_abort(self, message: str, state: str, exit_code: int, progress: dict | None = None) -> None:
        """A rank's error just before it aborts every rank (ranks.py): run.log gets the message and
        status.json the state ("failed", or "interrupted" for a second Ctrl-C) and the exit code
        every rank ends with (74, the files could not be written, tells a sweep to resume it, as
        on one rank), its progress kept, or `progress` (step, time) where given (no rank writes
        again). Best effort: the message is on stderr already."""
        status = self.read_status()
        status.pop("activity", None)  # the start's ("building the scene"), over with the run
        try:
            self.logger().log(logging.ERROR if state == "failed" else logging.WARNING, "%s", message)
            self.write_status(
                {**status, **(progress or {}), "state": state, "error": message, "exit_code": exit_code}
            )
        except OutputError:
            pass
        finally:
            self.close_logger()


class _WarningsToLog(logging.Handler):
    """While a run's log is open, every warning reaches run.log as well as stderr: Python
    warnings (warnings.warn, e.g. the drag's porosity floor) and the records of the library's
    loggers (`sphere.*`, e.g. the porosity clamp), which otherwise print to stderr only; and the
    library's notes (INFO, e.g. the porosity taken at porosity_max) to run.log alone."""

    def __init__(self, run_log: logging.Logger):
        super().__init__(logging.INFO)
        self.run_log = run_log
        self.library = logging.getLogger("sphere")
        self.library_level = self.library.level
        self.library.setLevel(logging.INFO)
        self.library.addHandler(self)
        self.case = logging.getLogger("sphere.case")  # (does not propagate to "sphere")
        self.case.addHandler(self)
        self.shown = warnings.showwarning
        warnings.showwarning = self._show

    def emit(self, record) -> None:
        message = record.getMessage()
        # the case's warnings print themselves; notes go to run.log alone
        if record.levelno >= logging.WARNING and not getattr(record, "printed", False):
            print(message, file=sys.stderr)
        self.run_log.log(record.levelno, "%s", message)

    def _show(self, message, category, filename, lineno, file=None, line=None) -> None:
        if self.shown is warnings._showwarning_orig:  # Python's own: as the case's warnings print
            print(f"sphere: warning: {message}", file=sys.stderr if file is None else file)
        else:  # a display the caller set up (a test runner, a notebook's) keeps its own form
            self.shown(message, category, filename, lineno, file, line)
        self.run_log.warning("%s: %s", category.__name__, message)

    def detach(self) -> None:
        self.library.removeHandler(self)
        self.library.setLevel(self.library_level)
        self.case.removeHandler(self)
        if warnings.showwarning == self._show:
            warnings.showwarning = self.shown


class _LogFile(logging.FileHandler):
    """run.log; a line that cannot be written (a full disk) is dropped, not printed as a
    traceback: the error that matters reaches the user on stderr anyway."""

    def handleError(self, record) -> None:
        pass


def _refuse_special(p: Path) -> None:
    """--overwrite never replaces /, the home directory, or the working directory or one above it."""
    target = p.resolve()
    cwd = Path.cwd().resolve()
    if target == Path(target.anchor) or target == Path.home().resolve() or cwd.is_relative_to(target):
        raise UsageError(
            f"{p}: --overwrite refused: {target} is the root, the home or the working directory "
            "(or holds it); give a run directory of its own with -o"
        )


class RunOutput:
    """Called by the loop on its schedules: frames, checkpoints."""

    def __init__(self, rundir: RunDirectory, scene, case_text: str, resolved: dict, physics_hash: str, log):
        self.rundir = rundir
        self.case_text = case_text
        self.resolved = resolved
        self.physics_hash = physics_hash
        self.log = log
        self.fields = list(scene.case.output.fields)
        self.trajectory = Trajectory(
            rundir.trajectory_path, self.fields, log, scene.state.particles.count > 0, rundir.hold_trajectory
        )
        self.keep = scene.case.output.checkpoints.keep
        self.last_checkpoint: Path | None = None
        self.xdmf_grids: list[tuple[str, str]] = []  # the sidecar's grids of each frame so far
        self.xdmf_written: float | None = None  # time.monotonic() of the sidecar's last write
        self.xdmf_behind = False  # frames in the trajectory that the sidecar does not list yet
        self.appending = False  # a frame's append has begun and not ended
        self.observables_follow_frames = scene.case.output.observables.follows_frames

    def frame(self, scene, last: bool = False) -> None:
        """A frame, its observables if they follow the frames, and the sidecar: rewritten with
        `last` (the run's end frame) or when it is XDMF_REFRESH_SECONDS old."""
        self.appending = True  # an interruption now may leave a frame without its views
        try:
            self.trajectory.append(scene)
        except TrajectoryLost as lost:
            self._trajectory_again(scene, lost)
            self.trajectory.append(scene)
        self.appending = False
        self.xdmf_behind = True
        if last or self.xdmf_written is None or time.monotonic() - self.xdmf_written >= XDMF_REFRESH_SECONDS:
            self._refresh_xdmf(scene)
        if self.observables_follow_frames:
            self.observe(scene)

    def close(self, scene) -> None:
        """The sidecar brought up to the trajectory's frames where a run ends without its end
        frame (a numerical failure, an interruption), unless a frame was being appended (its
        views may be missing: `sphere resume` rewrites the sidecar). Best effort: any error
        here is logged, never raised over the run's own."""
        if self.xdmf_behind and not self.appending:
            try:
                self._refresh_xdmf(scene)
            except Exception as exc:  # the file may be damaged in any way inside h5py
                self.log.error("%s: the ParaView sidecar not brought up to date (%s)", self.rundir.xdmf, exc)

    def first(self, scene) -> None:
        """The frame and observables of the starting state."""
        self.frame(scene)
        if not self.observables_follow_frames:
            self.observe(scene)

    def observe(self, scene) -> None:
        """One sample of the observables (on their schedule: computed only now)."""
        sample = scene.observer.sample()
        try:
            self.trajectory.append_observables(scene, sample)
        except TrajectoryLost as lost:
            self._trajectory_again(scene, lost)
            self.trajectory.append_observables(scene, sample)

    def _trajectory_again(self, scene, lost: TrajectoryLost) -> None:
        """trajectory.h5 deleted or emptied while the run goes on: a new one begins at this step,
        as `resume` begins one at its checkpoint, and run.log says so; the frames before went with
        the file (the checkpoints keep the state). The run goes on: the file is its output, not
        its state."""
        self.log.warning("%s; a new trajectory file begins at step %d", lost, scene.state.clock.step)
        self.trajectory.create(scene, self.case_text, self.resolved, self.physics_hash, provenance())
        self.xdmf_grids = []

    def _refresh_xdmf(self, scene) -> None:
        """Add the grids of the frames not yet in the sidecar (all of them after a resume) and
        replace it."""
        n = scene.state.particles.count
        fluid = _xdmf_fluid(scene)
        if n == 0 and fluid is None:  # no particles and no 3D fluid grid (vans1d alone): no sidecar
            return
        with open_as_writer(self.rundir.trajectory_path, "r") as f:
            times = frame_clock(f)["time"][...].tolist()
            moving = f"/fluid/{MOVING_GRID_SPACING}/value"
            spacing = f[moving][...] if moving in f else None
        grids = self.xdmf_grids[: len(times)]
        for k in range(len(grids), len(times)):
            frame_fluid = None
            if fluid is not None:
                grid, fields = fluid
                frame_fluid = (grid, fields, grid.spacing if spacing is None else spacing[k])
            grids.append(
                frame_grid(self.rundir.trajectory_path.name, k, times[k], n, self.fields, frame_fluid)
            )
        self.xdmf_grids = grids
        try:
            write_xdmf(self.rundir.xdmf, grids)
        except OSError as exc:
            raise OutputError(f"{self.rundir.xdmf}: cannot write the ParaView sidecar ({exc})") from None
        self.xdmf_written, self.xdmf_behind = time.monotonic(), False

    def checkpoint(self, scene) -> None:
        step = scene.state.clock.step
        if self.last_checkpoint is not None and self.last_checkpoint.name.endswith(f"{step:012d}.h5"):
            return
        self.last_checkpoint = write_checkpoint(
            self.rundir.checkpoints, scene, self.case_text, self.resolved, self.physics_hash, self.keep
        )
        self.rundir.checkpoint_written(self.last_checkpoint.name)
        self.log.info("checkpoint %s (t = %.6g s)", self.last_checkpoint.name, scene.state.clock.time)


def _xdmf_fluid(scene):
    """(grid, {field name: components}) of the fluid's 3D fields, or None."""
    fluid = scene.fluid
    grid = fluid.grid() if fluid is not None else None
    if grid is None:
        return None
    fields = {}
    for name, (value, _unit) in fluid.output_fields(scene.state).items():
        if is_grid_field(value, grid):
            fields[name] = 1 if value.ndim == 3 else value.shape[3]
    return grid, fields
