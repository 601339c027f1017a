"""Batch-job stops: SIGTERM/SIGUSR1 (sent by SLURM before a time limit), SIGHUP (the terminal
closed), Ctrl-C and the wall-time budget write a checkpoint at the next step and exit 75; the
run then resumes. Under nohup (SIGHUP ignored) a hang-up changes nothing."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import textwrap
import time
import weakref
from contextlib import contextmanager
from pathlib import Path
from types import SimpleNamespace

import pytest

from sphere_cli import api, runtime
from sphere_cli.config.load import parse_case
from sphere_cli.io.checkpoint import list_checkpoints, read_checkpoint
from sphere_cli.scene.builder import build_scene
from sphere_cli.simulation import Loop, StopFlag

CASE = """
    [simulation]
    duration = 20.0
    [domain]
    upper = [0.01, 0.01, 0.02]
    periodic = [true, true, false]
    [particles]
    count = 40
    density = 2500.0
    [contact]
    model = "linear"
    normal_stiffness = 1.0e4
    [[walls]]
    face = "z-"
    [output.frames]
    every_time = 1.0
    [output.checkpoints]
    every_time = 5.0
"""


def _as_started_from_a_terminal(nohup: bool):
    """The child's signals as a command typed in a terminal gets them, whatever this test process
    inherited: Ctrl-C's SIGINT handled (a background job of a non-interactive shell, as `make
    test &` runs the suite, starts with SIGINT ignored, and the run keeps a signal it was started
    ignoring), SIGHUP ignored under `nohup`."""

    def arrange() -> None:
        signal.signal(signal.SIGINT, signal.SIG_DFL)
        if nohup:
            signal.signal(signal.SIGHUP, signal.SIG_IGN)

    return arrange


def _start(tmp_path: Path, nohup: bool = False) -> tuple[subprocess.Popen, Path]:
    """The case run in a process of its own (`nohup`: started with SIGHUP ignored, as nohup
    starts it), once its time loop is running."""
    case = tmp_path / "case.toml"
    case.write_text(textwrap.dedent(CASE))
    run_dir = tmp_path / "run"
    proc = subprocess.Popen(
        [sys.executable, "-m", "sphere_cli.cli", "run", str(case), "-o", str(run_dir)],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_as_started_from_a_terminal(nohup),
    )
    deadline = time.monotonic() + 120
    log = run_dir / "run.log"
    while time.monotonic() < deadline:  # wait until the time loop is running
        if log.is_file() and "running from step" in log.read_text():
            break
        if proc.poll() is not None:
            pytest.fail(f"run ended early: {proc.communicate()}")
        time.sleep(0.05)
    time.sleep(0.3)
    return proc, run_dir


@pytest.mark.parametrize(
    "sig", [signal.SIGTERM, signal.SIGUSR1, signal.SIGHUP, signal.SIGINT], ids=lambda s: s.name
)
def test_signal_writes_checkpoint_and_exits_75(tmp_path: Path, sig):
    proc, run_dir = _start(tmp_path)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 75, err
    assert "Traceback" not in err
    assert "sphere resume" in err
    newest = read_checkpoint(list_checkpoints(run_dir / "checkpoints")[-1])
    assert newest.step > 0
    status = json.loads((run_dir / "status.json").read_text())
    assert status["state"] == "stopped" and status["step"] == newest.step
    result = api.resume(run_dir, until=newest.step * newest.dt + 0.01)
    assert result.status == "done"


def test_a_hang_up_under_nohup_changes_nothing(tmp_path: Path):
    """A run started ignoring SIGHUP (nohup) keeps running after one, and still stops politely
    on SIGTERM."""
    proc, run_dir = _start(tmp_path, nohup=True)
    proc.send_signal(signal.SIGHUP)
    time.sleep(1.0)
    assert proc.poll() is None, proc.communicate()
    assert "SIGHUP" not in (run_dir / "run.log").read_text()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 75, err
    assert "SIGTERM received" in (run_dir / "run.log").read_text()


def test_second_interrupt_stops_at_once(tmp_path: Path):
    proc, run_dir = _start(tmp_path)
    proc.send_signal(signal.SIGINT)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 75, err
    assert "Traceback" not in err
    for path in list_checkpoints(run_dir / "checkpoints"):
        read_checkpoint(path)  # every checkpoint left behind verifies


def test_wall_time_budget(tmp_path: Path):
    case = tmp_path / "case.toml"
    case.write_text(textwrap.dedent(CASE))
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "sphere_cli.cli",
            "run",
            str(case),
            "-o",
            str(tmp_path / "run"),
            "--max-wall-time",
            "1s",
        ],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 75, proc.stderr
    assert "wall-time" in proc.stderr
    assert len(list_checkpoints(tmp_path / "run" / "checkpoints")) >= 2


def test_second_interrupt_inside_a_finalizer_still_stops(capfd):
    """A signal lands between any two bytecodes, also inside a weakref callback, where Python
    drops the handler's KeyboardInterrupt and prints its traceback: the run must not print it
    and must still stop at the next step without its final checkpoint."""
    stop = StopFlag()

    class Body:
        pass

    with _sigint_handled(), runtime.signal_handlers(stop, enabled=True):
        signal.raise_signal(signal.SIGINT)  # the first: a checkpoint at the next step
        assert stop.reason == "SIGINT received" and not stop.interrupted
        body = Body()
        weakref.finalize(body, signal.raise_signal, signal.SIGINT)
        del body  # the second SIGINT is handled inside the finalizer
        assert stop.interrupted
    assert "Traceback" not in capfd.readouterr().err
    scene = build_scene(parse_case(textwrap.dedent(CASE)))
    loop = Loop(
        scene, 10, output=None, stop=stop, max_wall_seconds=None, progress=SimpleNamespace(interval=1.0)
    )
    with pytest.raises(KeyboardInterrupt):
        loop.run()
    assert scene.state.clock.step == 0


@contextmanager
def _sigint_handled():
    """SIGINT handled by Python, as in a process started from a terminal, whatever this test
    process inherited (_as_started_from_a_terminal)."""
    inherited = signal.signal(signal.SIGINT, signal.default_int_handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, inherited)
