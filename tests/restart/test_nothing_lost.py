"""Nothing is lost, whatever happens to a run: a kill before the first checkpoint, torn frames,
tampered or damaged checkpoints, a deleted trajectory, a second writer, a reader, --overwrite
of a directory that is not a run, a full disk.

Each test injects the damage at the instant it would happen (a child process that SIGKILLs
itself at a chosen call, or an edit of the files), then checks that the run ends as an
uninterrupted run does, bit for bit, or that the command refuses with a clear error and
leaves every file as it was.
"""

from __future__ import annotations

import errno
import fcntl
import hashlib
import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest
from restart_support import CASE, assert_same_state, final_state, frames, step_dt

from sphere_cli import api
from sphere_cli.errors import OutputError, RunBusy, UsageError
from sphere_cli.io import rundir as rundir_module
from sphere_cli.io import trajectory
from sphere_cli.io.checkpoint import list_checkpoints, read_checkpoint
from sphere_cli.io.rundir import RunDirectory

END = 400  # steps of the case


@pytest.fixture(scope="module")
def case(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("case")
    probe = root / "probe.toml"
    probe.write_text(textwrap.dedent(CASE.format(duration=1.0)))
    path = root / "case.toml"
    path.write_text(textwrap.dedent(CASE.format(duration=repr(END * step_dt(probe)))))
    return path


@pytest.fixture(scope="module")
def whole(case) -> Path:
    """The uninterrupted run (checkpoints at 200, 300, 400; frames every 50 steps)."""
    api.run(case, case.parent / "whole")
    return case.parent / "whole"


def _sphere(*args, cwd: Path, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "sphere_cli.cli", *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, **(env or {})},
    )


def _clean_error(result: subprocess.CompletedProcess, code: int, *fragments: str) -> None:
    shown = f"exit {result.returncode}\nstderr:\n{result.stderr}"
    assert result.returncode == code, shown
    assert "Traceback" not in result.stderr and "Exception ignored" not in result.stderr, shown
    errors = [line for line in result.stderr.splitlines() if line.startswith("sphere: error:")]
    assert len(errors) == 1, shown
    for fragment in fragments:
        assert fragment in result.stderr, f"{fragment!r} missing\n{shown}"


def _series(path: Path) -> dict[str, dict[str, np.ndarray]]:
    """Every step/time/value series of a trajectory file."""
    out = {}
    with h5py.File(path, "r") as f:

        def visit(name, obj):
            if isinstance(obj, h5py.Group) and "step" in obj:
                out[name] = {k: obj[k][...] for k in ("step", "time", "value")}

        f.visititems(visit)
    return out


def _assert_same_trajectory(a: Path, b: Path) -> None:
    """Every series of b holds exactly the samples of a: same steps, times and values."""
    sa, sb = _series(a / "trajectory.h5"), _series(b / "trajectory.h5")
    assert sa.keys() == sb.keys()
    for name in sa:
        for key in ("step", "time", "value"):
            assert np.array_equal(sa[name][key], sb[name][key]), f"{name}/{key} differs"


def _tree_digest(path: Path) -> dict[str, str]:
    return {
        str(p.relative_to(path)): hashlib.sha256(p.read_bytes()).hexdigest()
        for p in sorted(path.rglob("*"))
        if p.is_file()
    }


# --- a kill before the first checkpoint --------------------------------------------------------

KILL_AT = """
import os, signal, sys
from sphere_cli.io import checkpoint, rundir, trajectory

where = sys.argv[3]

def die(*args, **kwargs):
    os.kill(os.getpid(), signal.SIGKILL)

def before_case(path, text):
    if path.name == "case.toml":
        die()
    write_text_atomic(path, text)

if where == "before-case":  # the directory and its marker exist, case.toml does not
    write_text_atomic, rundir.write_text_atomic = rundir.write_text_atomic, before_case
elif where == "after-case":  # case.toml is written, nothing else yet
    trajectory.Trajectory.create = die
else:  # the first frame is written, the first checkpoint is about to be published
    checkpoint.publish = die
from sphere_cli import api
api.run(sys.argv[1], sys.argv[2], overwrite=len(sys.argv) > 4)
"""


def _killed_run(case: Path, run: Path, where: str, overwrite: bool = False) -> None:
    script = case.parent / "kill_at.py"
    script.write_text(KILL_AT)
    args = [sys.executable, str(script), str(case), str(run), where] + (["overwrite"] if overwrite else [])
    child = subprocess.run(args, capture_output=True, text=True)
    assert child.returncode == -9, child.stderr
    assert not list_checkpoints(run / "checkpoints")


@pytest.mark.parametrize("where", ["after-case", "before-first-checkpoint"])
def test_kill_before_the_first_checkpoint_resumes_from_step_0(case, whole, tmp_path, where):
    run = tmp_path / "killed"
    _killed_run(case, run, where)
    assert (run / "case.toml").is_file()
    result = _sphere("resume", run, "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "starting again from step 0" in (run / "run.log").read_text()
    assert_same_state(final_state(whole), final_state(run))
    _assert_same_trajectory(whole, run)


@pytest.mark.parametrize("gone", ["emptied", "deleted"])
def test_a_resume_without_the_checkpoints_the_run_wrote_is_refused(whole, tmp_path, gone):
    """Checkpoints deleted after the run wrote some (to free space, a scratch purge): resuming
    from step 0 would rewrite the trajectory, whose frames may be all that is left of a long run.
    Refused (exit 66) naming the newest checkpoint status.json recorded, trajectory and status
    untouched; run.log says why."""
    run = tmp_path / "run"
    shutil.copytree(whole, run)
    assert json.loads((run / "status.json").read_text())["checkpoint"] == "ckpt-000000000400.h5"
    shutil.rmtree(run / "checkpoints")
    if gone == "emptied":
        (run / "checkpoints").mkdir()
    kept = {name: (run / name).read_bytes() for name in ("trajectory.h5", "status.json")}
    result = _sphere("resume", run, "-q", cwd=tmp_path)
    _clean_error(result, 66, "holds no checkpoint", "wrote ckpt-000000000400.h5", "--overwrite")
    assert {name: (run / name).read_bytes() for name in kept} == kept
    assert "holds no checkpoint" in (run / "run.log").read_text()


def test_kill_before_the_case_is_written_leaves_a_directory_run_accepts(case, whole, tmp_path):
    """What a batch script does when RUN_DIR has no case.toml: `sphere run` again, no --overwrite."""
    run = tmp_path / "killed"
    _killed_run(case, run, "before-case")
    assert not (run / "case.toml").exists()
    result = _sphere("run", case, "-o", run, "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert_same_state(final_state(whole), final_state(run))
    _assert_same_trajectory(whole, run)


# --- torn frames ---------------------------------------------------------------------------------


def _tear(path: Path) -> None:
    """What a kill during an append leaves: series resized with a last step never written (0),
    and step, time and value of unequal length."""
    with h5py.File(path, "a") as f:
        torn = ("particles/trajectory/position", "particles/trajectory/velocity", "observables/contacts")
        for name in torn:
            group = f[name]
            for key in ("step", "time", "value"):
                group[key].resize(group[key].shape[0] + 1, axis=0)
        group = f["particles/trajectory/force"]
        group["step"].resize(group["step"].shape[0] + 1, axis=0)
        group["step"][-1] = 10**9


@pytest.mark.parametrize("resume_from", ["newest", "older"])
def test_torn_frames_are_cut_to_the_checkpoint_on_resume(case, whole, tmp_path, resume_from):
    run = tmp_path / "torn"
    api.run(case, run, until=250 * step_dt(case))
    if resume_from == "older":
        list_checkpoints(run / "checkpoints")[-1].unlink()  # resume from 200: frames at 250 go too
    _tear(run / "trajectory.h5")
    api.resume(run)
    series = _series(run / "trajectory.h5")
    for name, s in series.items():
        assert s["step"].size == s["time"].size == s["value"].shape[0], name
        assert np.all(np.diff(s["step"]) > 0), name
    assert series["particles/trajectory/position"]["step"].tolist() == list(range(0, END + 1, 50))
    assert_same_state(final_state(whole), final_state(run))
    _assert_same_trajectory(whole, run)


# --- what is read back from a checkpoint ---------------------------------------------------------


def _tamper_attribute(path: Path, name: str) -> None:
    with h5py.File(path, "r+") as f:
        value = f.attrs[name]
        f.attrs[name] = value + "0" if isinstance(value, str) else value * 2 + 1


def _tamper_scalar(path: Path) -> None:
    with h5py.File(path, "r+") as f:
        scalars = []
        f["sphere/state"].visititems(lambda n, o: scalars.append(o) if isinstance(o, h5py.Dataset) else None)
        scalar = next(ds for ds in scalars if ds.ndim == 0 and ds.dtype.kind in "iuf")
        scalar[()] = scalar[()] + 1


def _damage_object_header(path: Path) -> None:
    """Garble the object header of the positions (no checksum of HDF5's own covers it)."""
    with h5py.File(path, "r") as f:
        address = h5py.h5o.get_info(f["sphere/state/particles/pos"].id).addr
    with open(path, "r+b") as raw:
        raw.seek(address + 4)
        raw.write(b"\xff" * 48)


DAMAGE = {
    "step": lambda p: _tamper_attribute(p, "step"),
    "dt": lambda p: _tamper_attribute(p, "dt"),
    "time": lambda p: _tamper_attribute(p, "time"),
    "physics_hash": lambda p: _tamper_attribute(p, "physics_hash"),
    "scalar-dataset": _tamper_scalar,
    "object-header": _damage_object_header,
}


@pytest.mark.parametrize("damage", DAMAGE)
def test_damaged_newest_checkpoint_falls_back_to_the_previous(whole, tmp_path, damage):
    run = tmp_path / "run"
    shutil.copytree(whole, run)
    newest = list_checkpoints(run / "checkpoints")[-1]
    DAMAGE[damage](newest)
    with pytest.raises(OutputError):
        read_checkpoint(newest)
    summary = api.inspect(run)
    assert [c["valid"] for c in summary["checkpoints"]] == [True, True, False]
    _clean_error(_sphere("inspect", newest, cwd=tmp_path), 74, newest.name)
    result = _sphere("resume", run, "-q", cwd=tmp_path)  # neither a traceback nor "the case changed" (78)
    assert result.returncode == 0, result.stderr
    log = (run / "run.log").read_text()
    assert f"skipping {newest.name}" in log and "resuming from ckpt-000000000300.h5" in log
    assert_same_state(final_state(whole), final_state(run))


# --- the trajectory and its sidecar on resume ----------------------------------------------------


@pytest.mark.parametrize("damage", ["deleted", "empty"])
def test_a_lost_trajectory_starts_again_from_the_checkpoint(case, whole, tmp_path, damage):
    run = tmp_path / "run"
    api.run(case, run, until=250 * step_dt(case))
    path = run / "trajectory.h5"
    path.unlink() if damage == "deleted" else path.write_bytes(b"")
    result = _sphere("resume", run, "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert "a new trajectory file starts at ckpt-000000000250.h5" in (run / "run.log").read_text()
    kept = frames(run)
    assert sorted(kept) == list(range(250, END + 1, 50))
    for step, value in frames(whole).items():
        if step >= 250:
            assert np.array_equal(kept[step], value)
    assert_same_state(final_state(whole), final_state(run))


def test_a_sidecar_replaced_by_a_directory_is_a_clear_error(whole, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(whole, run)
    (run / "trajectory.xmf").unlink()
    (run / "trajectory.xmf").mkdir()
    before = _tree_digest(run)
    result = _sphere("resume", run, "-q", "--until", 1.0, cwd=tmp_path)
    _clean_error(result, 74, "trajectory.xmf", "not a file")
    assert _tree_digest(run) == before


# --- one writer, any number of readers -----------------------------------------------------------

HOLD = """
import sys, time
{take}
print("holding", flush=True)
time.sleep(120)
"""


def _holder(take: str) -> subprocess.Popen:
    child = subprocess.Popen(
        [sys.executable, "-c", HOLD.format(take=take)], stdout=subprocess.PIPE, text=True
    )
    assert child.stdout.readline().strip() == "holding"
    return child


def test_a_second_writer_is_refused(case, whole, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(whole, run)
    before = _tree_digest(run)
    holder = _holder(f"from sphere_cli.io.rundir import RunDirectory\nRunDirectory({str(run)!r}).lock()")
    try:
        for args in (("resume", run, "--until", 1.0), ("run", case, "-o", run, "--overwrite")):
            _clean_error(_sphere(*args, "-q", cwd=tmp_path), 73, str(run), "another sphere process")
        assert _tree_digest(run) == before
        with pytest.raises(RunBusy):
            RunDirectory(run).lock()
    finally:
        holder.kill()
        holder.wait()
    released = RunDirectory(run)
    released.lock()  # released with its holder
    released.unlock()


@pytest.mark.parametrize("answer", [errno.ENOLCK, errno.ENOSYS], ids=["nfs-without-lockd", "no-flock"])
def test_a_file_system_that_cannot_lock_runs_unguarded_and_says_so(
    case, whole, tmp_path, monkeypatch, capsys, answer
):
    """NFS without its lock service answers flock with ENOLCK, a Lustre client mounted without
    flock with ENOSYS: the run and its resume go on (they were refused with exit 74, so no run
    could be made on such a scratch file system), each saying in run.log that nothing guards the
    directory against a second writer; the result is the uninterrupted run's."""

    def flock(fd, operation):
        raise OSError(answer, os.strerror(answer))

    monkeypatch.setattr(rundir_module.fcntl, "flock", flock)
    run = tmp_path / "run"
    half = read_checkpoint(list_checkpoints(whole / "checkpoints")[0])
    api.run(case, run, until=half.step * half.dt)
    api.resume(run)
    log = (run / "run.log").read_text()
    warning = f"WARNING {run}: its file system cannot lock files ({os.strerror(answer)}): nothing keeps"
    assert log.count(warning) == 2, log
    assert capsys.readouterr().err.count("sphere: warning: " + warning.removeprefix("WARNING ")) == 2
    assert not RunDirectory(run).busy()  # nothing to probe: never taken for a run in use
    assert_same_state(final_state(whole), final_state(run))


def test_a_checkpoint_whose_lock_cannot_be_taken_is_read_as_it_is(whole, tmp_path):
    """HDF5 locks a file it opens (h5py's default); where that fails (NFS without its lock
    service, a program holding the file open for writing: here an exclusive lock held by this
    test), sphere read the newest checkpoint as corrupt and resumed from the one before. Its
    reads take no lock: the checkpoint verifies, inspect lists it valid (the trajectory locked
    too), and resume starts there (the trajectory then free: one held open to write stops a
    resume, test_a_trajectory_open_to_write_elsewhere_stops_a_resume_before_it_writes)."""
    run = tmp_path / "run"
    shutil.copytree(whole, run)
    newest = list_checkpoints(run / "checkpoints")[-1]
    held = [os.open(path, os.O_RDONLY) for path in (newest, run / "trajectory.h5")]
    try:
        for fd in held:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        with pytest.raises(OSError, match="unable to lock file"):
            h5py.File(newest, "r")  # what a default open meets
        assert read_checkpoint(newest).step == END
        listed = api.inspect(run)["checkpoints"]
        assert [(c["step"], c["valid"]) for c in listed][-1] == (END, True), listed
        os.close(held.pop())  # the trajectory's
        api.resume(run, until=(END + 20) * read_checkpoint(newest).dt)
    finally:
        for fd in held:
            os.close(fd)
    assert f"resuming from {newest.name}" in (run / "run.log").read_text()


def test_a_resume_goes_on_while_a_reader_holds_the_trajectory(case, whole, tmp_path):
    """h5py's default open takes HDF5's file lock; the run's writes ignore it (the run directory's
    lock keeps the one writer), so the resumed run cuts and appends frames as if no one read."""
    run = tmp_path / "run"
    half = repr(END // 2 * step_dt(case))
    assert _sphere("run", case, "-o", run, "-q", "--until", half, cwd=tmp_path).returncode == 0
    reader = _holder(f"import h5py\nf = h5py.File({str(run / 'trajectory.h5')!r}, 'r')")
    try:
        result = _sphere("resume", run, "-q", cwd=tmp_path)
        assert reader.poll() is None, "the reader must still hold the file"
    finally:
        reader.kill()
        reader.wait()
    assert result.returncode == 0, result.stderr
    assert_same_state(final_state(whole), final_state(run))
    _assert_same_trajectory(whole, run)
    assert not list(run.glob("trajectory.unreadable-*"))


LONG = 40  # the whole-run reader's case runs LONG times END steps: 320 frames, several seconds


def test_a_run_goes_on_while_readers_hold_and_inspect_it(tmp_path):
    """A notebook opens trajectory.h5 as soon as it appears and holds it to the end, and
    `sphere inspect` reads the run while it goes: the run ends with every frame. The inspection
    runs in its own process, as a user's would: in this one HDF5 would hand it the held file's
    view, fixed at the moment it was opened."""
    probe = tmp_path / "probe.toml"
    probe.write_text(textwrap.dedent(CASE.format(duration=1.0)))
    case = tmp_path / "case.toml"
    case.write_text(textwrap.dedent(CASE.format(duration=repr(LONG * END * step_dt(probe)))))
    run = tmp_path / "run"
    proc = subprocess.Popen(
        [sys.executable, "-m", "sphere_cli.cli", "run", case, "-o", run, "-q"],
        stderr=subprocess.PIPE,
        text=True,
    )
    held = None
    seen = inspected = None
    try:
        while proc.poll() is None and held is None:
            try:
                held = h5py.File(run / "trajectory.h5", "r")  # default locking, as a notebook
                seen = held["particles/trajectory/position/step"].shape[0]
            except (OSError, KeyError):  # not there yet, or caught while being created
                held = None
        while proc.poll() is None and not inspected:  # (the file is made before its first frame)
            shown = _sphere("inspect", run, "--json", cwd=tmp_path)
            assert shown.returncode == 0, shown.stderr
            inspected = json.loads(shown.stdout).get("trajectory", {}).get("frames")
        stderr = proc.communicate(timeout=600)[1]
    finally:
        proc.kill()
        if held is not None:
            held.close()
    assert proc.returncode == 0, stderr
    total = LONG * END // 50 + 1
    assert seen is not None and seen < total, "the reader must open the file while the run goes on"
    assert inspected and inspected <= total, "sphere inspect must read frames while the run goes on"
    steps = frames(run)
    assert sorted(steps) == list(range(0, LONG * END + 1, 50))


@pytest.fixture
def quick_retries(monkeypatch):
    monkeypatch.setattr(trajectory, "WRITE_RETRY_DELAYS", (0.0, 0.0, 0.0))


def _failing(monkeypatch, fail_calls: set[int]):
    """open_as_writer raises OSError at the appends numbered in fail_calls (0 = the first)."""
    real = trajectory.open_as_writer
    calls = []

    def flaky(path, mode):
        if mode == "a":
            calls.append(mode)
            if len(calls) - 1 in fail_calls:
                raise OSError(5, "Input/output error (injected)")
        return real(path, mode)

    monkeypatch.setattr(trajectory, "open_as_writer", flaky)


def test_a_failed_frame_write_is_retried_and_logged(case, whole, tmp_path, monkeypatch, quick_retries):
    _failing(monkeypatch, {3, 4})  # two failed tries of one write, then it goes through
    run = tmp_path / "run"
    api.run(case, run)
    log = (run / "run.log").read_text()
    assert log.count("trying again in 0 s") == 2, log
    assert "Input/output error (injected)" in log and "at try 3" in log, log
    _assert_same_trajectory(whole, run)


def test_a_frame_that_cannot_be_written_fails_after_the_retries(case, tmp_path, monkeypatch, quick_retries):
    _failing(monkeypatch, set(range(6, 10_000)))
    run = tmp_path / "run"
    with pytest.raises(OutputError, match="4 tries"):
        api.run(case, run)
    log = (run / "run.log").read_text()
    assert log.count("trying again") == len(trajectory.WRITE_RETRY_DELAYS), log
    read_checkpoint(list_checkpoints(run / "checkpoints")[-1])  # the newest checkpoint verifies


# --- --overwrite ---------------------------------------------------------------------------------


@pytest.mark.parametrize("where", ["root", "home", "cwd", "above-cwd"])
def test_overwrite_refuses_the_root_home_and_working_directories(tmp_path, monkeypatch, where):
    home = tmp_path / "home"
    (home / "work").mkdir(parents=True)
    (home / "work" / "notes.txt").write_text("mine")
    (home / RunDirectory(home).marker.name).write_text("")  # even one that looks like a run
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.chdir(home / "work")
    target = {"root": Path("/"), "home": home, "cwd": Path("."), "above-cwd": Path("..")}[where]
    with pytest.raises(UsageError, match="root, the home or the working directory"):
        RunDirectory(target).check_new(overwrite=True)


def test_overwrite_of_the_working_directory_deletes_nothing(whole, case, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(whole, run)
    before = _tree_digest(run)
    _clean_error(_sphere("run", case, "-o", ".", "--overwrite", "-q", cwd=run), 2, "working directory")
    assert _tree_digest(run) == before


def test_overwrite_refuses_a_file_sphere_did_not_write_inside_checkpoints(whole, case, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(whole, run)
    (run / "checkpoints" / "notes.txt").write_text("mine")
    before = _tree_digest(run)
    result = _sphere("run", case, "-o", run, "--overwrite", "-q", cwd=tmp_path)
    _clean_error(result, 2, "files sphere did not write", "checkpoints/notes.txt")
    assert _tree_digest(run) == before


def test_overwrite_keeps_the_old_run_until_the_first_checkpoint(whole, case, tmp_path, monkeypatch):
    run = tmp_path / "run"
    shutil.copytree(whole, run)
    before = _tree_digest(run)

    def fail(*args, **kwargs):
        raise OutputError("the first checkpoint failed")

    monkeypatch.setattr("sphere_cli.io.rundir.write_checkpoint", fail)
    with pytest.raises(OutputError):
        api.run(case, run, overwrite=True)
    assert _tree_digest(run) == before, "a new run that failed must give the old one back"
    assert not list(tmp_path.glob(".run.replaced-*"))

    _killed_run(case, run, "before-first-checkpoint", overwrite=True)
    (aside,) = tmp_path.glob(".run.replaced-*")
    assert _tree_digest(aside) == before, "a kill must leave the old run whole beside the new one"

    monkeypatch.undo()
    shutil.rmtree(aside)
    shutil.rmtree(run)
    shutil.copytree(whole, run)
    api.run(case, run, overwrite=True)
    assert not list(tmp_path.glob(".run.replaced-*")), "the old run goes once the new one can resume"
    assert_same_state(final_state(whole), final_state(run))


# --- a full disk ---------------------------------------------------------------------------------

FULL_DISK_CASE = CASE.replace("count = 40", "count = 400").replace(
    "upper = [0.01, 0.01, 0.02]", "upper = [0.03, 0.03, 0.04]"
)


@pytest.fixture
def small_disk(tmp_path):
    """A 3 MiB tmpfs (needs root and mount(2): skipped elsewhere)."""
    mount = tmp_path / "disk"
    mount.mkdir()
    try:
        subprocess.run(
            ["mount", "-t", "tmpfs", "-o", "size=3m", "tmpfs", str(mount)], check=True, capture_output=True
        )
    except (OSError, subprocess.CalledProcessError) as exc:
        pytest.skip(f"cannot mount a small tmpfs here ({exc}); the full-disk test needs root")
    yield mount
    subprocess.run(["umount", "-l", str(mount)], capture_output=True)


def _sphere_without_waits(*args, cwd: Path, unseen: bool = False) -> subprocess.CompletedProcess:
    """`sphere ARGS` in its own process, with the pauses between a failed write's tries (7 s in
    all, for a disk that frees space) cut to nothing: the tries themselves are as many. `unseen`:
    the free-space check before each HDF5 write off, as a disk quota escapes it."""
    command = (
        "import sys; from sphere_cli.io import trajectory; from sphere_cli.cli import main; "
        "trajectory.WRITE_RETRY_DELAYS = (0.0,) * len(trajectory.WRITE_RETRY_DELAYS); "
        + ("trajectory.require_free_space = lambda *args: None; " if unseen else "")
        + "sys.argv[0] = 'sphere'; main()"
    )
    return subprocess.run(
        [sys.executable, "-c", command, *map(str, args)], cwd=cwd, capture_output=True, text=True, timeout=600
    )


@pytest.mark.parametrize("schedule", ["frames", "checkpoints", "unseen"])
def test_a_full_disk_stops_cleanly_and_resumes_bitwise(tmp_path, small_disk, schedule):
    """frames: the trajectory fills the disk; checkpoints: 20 kept checkpoints fill it between
    frames; unseen: the frames fill it with the free-space check before each HDF5 write off, as
    a user's disk quota escapes it (the file system does not report it): HDF5 meets the limit
    inside its own writes and h5py reports the flush that fails as the file closes as
    RuntimeError, which ended the run with a traceback and exit 1. Each way: exit 74 and one
    line naming the cause, status.json failed, and once there is room resume ends as the
    uninterrupted run (unseen: the trajectory it may have damaged set aside, its frames kept)."""
    frames_every, checkpoints_every, keep = (50, 5, 20) if schedule == "checkpoints" else (5, 100, 3)
    text = FULL_DISK_CASE.replace("every_steps = 50", f"every_steps = {frames_every}")
    text = text.replace("every_steps = 100", f"every_steps = {checkpoints_every}")
    text = text.replace("keep = 3", f"keep = {keep}")
    probe = tmp_path / "probe.toml"
    probe.write_text(textwrap.dedent(text.format(duration=1.0)))
    case = tmp_path / "case.toml"
    case.write_text(textwrap.dedent(text.format(duration=repr(END * step_dt(probe)))))
    api.run(case, tmp_path / "whole")

    run = small_disk / "run"
    result = _sphere_without_waits("run", case, "-o", run, "-q", cwd=tmp_path, unseen=schedule == "unseen")
    _clean_error(result, 74, "No space left on device", f"{len(trajectory.WRITE_RETRY_DELAYS) + 1} tries")
    if schedule != "checkpoints":  # frames that cannot fit are said at the start
        assert "sphere: warning: the " in result.stderr and "frames still to write" in result.stderr
    # a batch job's monitor reads that it failed, where and why (status.json is small: it fits)
    status = json.loads((run / "status.json").read_text())
    assert status["state"] == "failed" and "No space left on device" in status["error"], status
    assert status["exit_code"] == 74  # a sweep resumes such a member (sphere_cli/sweep.py member_state)
    newest = list_checkpoints(run / "checkpoints")[-1]
    assert status["step"] >= read_checkpoint(newest).step
    assert read_checkpoint(newest).step < END
    subprocess.run(["mount", "-o", "remount,size=64m", str(small_disk)], check=True)
    result = _sphere("resume", run, "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    assert_same_state(final_state(tmp_path / "whole"), final_state(run))
    if schedule != "unseen":
        _assert_same_trajectory(tmp_path / "whole", run)
    for aside in run.glob("trajectory.unreadable-*.h5"):
        assert aside.stat().st_size > 0


def test_a_fault_of_the_program_mid_run_is_recorded_and_the_run_resumes(case, whole, monkeypatch):
    """An exception that is no error of the case (a bug) in the steps: run.log holds its
    traceback, status.json says failed with the error, the frames written are readable and
    the newest checkpoint resumes to the uninterrupted run's end, bitwise."""
    from sphere_cli import simulation

    real = simulation.advance

    def advance_then_fail(scene, steps, sync=True):
        if scene.state.clock.step >= 250:
            raise ZeroDivisionError("planted fault")
        return real(scene, steps, sync)

    monkeypatch.setattr(simulation, "advance", advance_then_fail)
    run_dir = case.parent / "faulty"
    with pytest.raises(ZeroDivisionError, match="planted fault"):
        api.run(case, run_dir)
    status = json.loads((run_dir / "status.json").read_text())
    assert status["state"] == "failed" and status["step"] >= 250
    assert status["error"] == f"internal error at step {status['step']}: ZeroDivisionError: planted fault"
    log = (run_dir / "run.log").read_text()
    assert "ZeroDivisionError: planted fault" in log and "Traceback" in log
    assert frames(run_dir).keys() <= frames(whole).keys() and max(frames(run_dir)) >= 200
    monkeypatch.setattr(simulation, "advance", real)
    api.resume(run_dir)
    assert_same_state(final_state(run_dir), final_state(whole))


@pytest.mark.parametrize("stop", ["refused", "interrupted"])
def test_a_resume_that_stops_before_its_first_step_leaves_the_status_as_it_was(
    whole, tmp_path, monkeypatch, stop
):
    """`sphere resume RUN --device cuda` where no GPU can be used is refused while the scene is
    built, and Ctrl-C may come while its kernels compile: nothing of the run changed, so
    status.json says again what it said ("done" at the last step), not "starting" for good,
    and run.log says why the resume did not start."""
    from sphere_cli import api as api_module
    from sphere_cli.errors import UsageError

    run = tmp_path / "run"
    shutil.copytree(whole, run)
    before = (run / "status.json").read_text()
    assert json.loads(before)["state"] == "done"
    error = UsageError("no GPU can be used here") if stop == "refused" else KeyboardInterrupt()

    def build_fails(*args, **kwargs):
        assert json.loads((run / "status.json").read_text())["state"] == "starting"
        raise error

    monkeypatch.setattr(api_module, "build_scene", build_fails)
    with pytest.raises(type(error)):
        api.resume(run, until=2 * json.loads(before)["time"])
    assert (run / "status.json").read_text() == before
    if stop == "refused":
        assert (
            "the resume stopped before its first step: no GPU can be used here"
            in (run / "run.log").read_text()
        )


def test_a_trajectory_open_to_write_elsewhere_stops_a_resume_before_it_writes(whole, tmp_path):
    """A notebook holds trajectory.h5 open in h5py's "r+" (HDF5's exclusive lock): the resume
    used to append its frames beside it, and the notebook's close then left the whole file
    unreadable (addr overflow). Now the resume stops before its first step, exit 74, naming the
    file and what to do, the file and status.json untouched; once the notebook closes it, the
    resume goes on and the trajectory reads to its end."""
    run = tmp_path / "run"
    shutil.copytree(whole, run)
    before = {name: (run / name).read_bytes() for name in ("trajectory.h5", "status.json")}
    end = 2 * json.loads(before["status.json"])["time"]
    with h5py.File(run / "trajectory.h5", "r+"):
        result = _sphere("resume", run, "--until", repr(end), "-q", cwd=tmp_path)
        assert result.returncode == 74, result.stderr
        assert "open for writing in another program" in result.stderr and "Traceback" not in result.stderr
    assert {name: (run / name).read_bytes() for name in before} == before
    result = _sphere("resume", run, "--until", repr(end), "-q", cwd=tmp_path)
    assert result.returncode == 0, result.stderr
    steps = frames(run)
    assert max(steps) == json.loads((run / "status.json").read_text())["step"] > max(frames(whole))


def test_a_program_opening_the_trajectory_to_write_is_refused_while_the_run_goes_on(tmp_path):
    """While a run writes trajectory.h5, another program's h5py.File(path, "r+") fails at once
    ("unable to lock file": the run holds a shared lock, as readers do) instead of opening the
    file to write beside the run; the run ends with every frame, readable."""
    probe = tmp_path / "probe.toml"
    probe.write_text(textwrap.dedent(CASE.format(duration=1.0)))
    case = tmp_path / "case.toml"
    case.write_text(textwrap.dedent(CASE.format(duration=repr(LONG * END * step_dt(probe)))))
    run = tmp_path / "run"
    proc = subprocess.Popen([sys.executable, "-m", "sphere_cli.cli", "run", case, "-o", run, "-q"])
    opening = f"import h5py; h5py.File({str(run / 'trajectory.h5')!r}, 'r+')"
    writers = []
    try:
        while proc.poll() is None and not writers:
            if list_checkpoints(run / "checkpoints"):  # the trajectory has its first frame
                writers.append(
                    subprocess.run(
                        [sys.executable, "-c", opening], capture_output=True, text=True, timeout=60
                    )
                )
        proc.wait(timeout=600)
    finally:
        proc.kill()
    assert proc.returncode == 0
    assert writers, "the run ended before a writer could try to open its trajectory"
    assert writers[0].returncode != 0 and "unable to lock file" in writers[0].stderr, writers[0].stderr
    assert sorted(frames(run)) == list(range(0, LONG * END + 1, 50))


@pytest.mark.parametrize("how", ["deleted", "emptied"])
def test_a_trajectory_deleted_during_the_run_begins_again_and_the_run_goes_on(case, whole, tmp_path, how):
    """A scratch purge or a clean-up deletes (or empties) trajectory.h5 while the run writes it:
    the next frame's append made a new empty HDF5 file and failed inside it (KeyError, a
    traceback, exit 1). Now a new trajectory begins at that frame's step, run.log says so, and
    the run ends as the uninterrupted one (the file is its output, not its state)."""
    from sphere_cli.io.rundir import RunOutput

    run = tmp_path / "run"
    real = RunOutput.frame

    def frame(self, scene, last=False):
        if scene.state.clock.step == 250:
            if how == "deleted":
                self.rundir.trajectory_path.unlink()
            else:
                self.rundir.trajectory_path.write_bytes(b"")
        return real(self, scene, last)

    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(RunOutput, "frame", frame)
        api.run(case, run)
    assert (
        "deleted or emptied while the run writes it; a new trajectory file begins at step 250"
        in (run / "run.log").read_text()
    )
    assert sorted(frames(run)) == list(range(250, END + 1, 50))
    assert_same_state(final_state(whole), final_state(run))
    kept = frames(whole)
    for step, value in frames(run).items():
        np.testing.assert_array_equal(value, kept[step])
