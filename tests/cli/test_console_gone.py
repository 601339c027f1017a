"""A console that goes away does not end a run (sphere_cli/io/console.py): `sphere run case.toml
| head` whose reader exits, a `tee` that dies. The run is a real process whose stdout and stderr
are pipes closed before it prints anything; it must end as a run with its console does, with the
loss noted in run.log. A console that is there but reads late (a full non-blocking pipe) gets
every line; one that stops reading is waited for once, then its lines are dropped until it reads
again."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import time

import h5py
import numpy as np
import pytest
from cli_test_support import TINY, TINY_END_STEP

from sphere_cli.io import console
from sphere_cli.io.console import GuardedStream


def _run(case_dir, out: str, closed: bool) -> int:
    proc = subprocess.Popen(
        [sys.executable, "-m", "sphere_cli.cli", "run", "case.toml", "-o", out],
        cwd=case_dir,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
    )
    if closed:  # the reader leaves at once: every write of the run meets a broken pipe
        proc.stdout.close()
        proc.stderr.close()
        return proc.wait(timeout=600)
    proc.communicate(timeout=600)
    return proc.returncode


def test_a_command_whose_reader_leaves_early_ends_without_a_word():
    """`sphere schema | head -1`: the reader leaves after a line; a command without a run log
    ends as other tools do, saying nothing (it said that run.log kept the record)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "sphere_cli.cli", "schema"], stdout=subprocess.PIPE, stderr=subprocess.PIPE
    )
    assert proc.stdout.readline().strip() == b"{"
    proc.stdout.close()
    stderr = proc.stderr.read()
    assert proc.wait(timeout=60) == 0
    assert stderr == b"", stderr


def test_a_run_whose_console_is_gone_ends_as_one_with_its_console(tmp_path):
    (tmp_path / "case.toml").write_text(TINY)
    assert _run(tmp_path, "gone", closed=True) == 0
    assert _run(tmp_path, "kept", closed=False) == 0
    status = json.loads((tmp_path / "gone" / "status.json").read_text())
    assert status["state"] == "done" and status["step"] == TINY_END_STEP
    log = (tmp_path / "gone" / "run.log").read_text()
    assert "stdout is gone (BrokenPipeError" in log or "stderr is gone (BrokenPipeError" in log, log
    assert "internal error" not in log
    with (
        h5py.File(tmp_path / "gone" / "trajectory.h5", "r") as gone,
        h5py.File(tmp_path / "kept" / "trajectory.h5", "r") as kept,
    ):
        series = "particles/trajectory/position"
        assert np.array_equal(gone[f"{series}/step"][:], kept[f"{series}/step"][:])
        assert np.array_equal(gone[f"{series}/value"][:], kept[f"{series}/value"][:])


class _Broken:
    """A stream whose reader has left."""

    def __init__(self):
        self.writes = 0

    def write(self, text):
        self.writes += 1
        raise BrokenPipeError(32, "Broken pipe")

    def flush(self):
        raise BrokenPipeError(32, "Broken pipe")

    def isatty(self):
        return True

    def fileno(self):
        raise OSError("no descriptor")


def test_a_guarded_stream_stops_writing_after_its_first_failure(caplog):
    broken = _Broken()
    stream = GuardedStream(broken, "stderr")
    assert stream.isatty()
    assert stream.write("first\n") == len("first\n")
    stream.write("second\n")
    stream.flush()
    assert broken.writes == 1 and stream.gone and not stream.isatty()
    assert [r.getMessage() for r in caplog.records if "is gone" in r.getMessage()] == [
        "stderr is gone (BrokenPipeError: [Errno 32] Broken pipe): nothing more is printed there; "
        "run.log keeps the record"
    ]


class _Latin1:
    """A console that cannot show every character (a Latin-1 terminal)."""

    encoding = "latin-1"

    def __init__(self):
        self.text = ""

    def write(self, text):
        text.encode(self.encoding)  # raises UnicodeEncodeError as a text stream would
        self.text += text
        return len(text)


def test_a_character_the_console_cannot_show_is_replaced_not_taken_for_a_lost_console():
    console = _Latin1()
    stream = GuardedStream(console, "stderr")
    stream.write("phi >= 0.61 \u2265 \u03c6\n")
    stream.write("next\n")
    assert not stream.gone
    assert console.text == "phi >= 0.61 ? ?\nnext\n"


def _full_pipe() -> tuple[int, int, int]:
    """A pipe whose write end is non-blocking (as some launchers leave a child's stdout) and full:
    (read end, write end, bytes in it)."""
    read, write = os.pipe()
    os.set_blocking(write, False)
    filled = 0
    try:
        while True:
            filled += os.write(write, b"x" * 4096)
    except BlockingIOError:
        pass
    return read, write, filled


@pytest.mark.parametrize("unbuffered", [False, True], ids=["buffered", "unbuffered"])
def test_a_console_that_reads_late_gets_every_line(tmp_path, unbuffered):
    """stdout and stderr a non-blocking pipe that is full when the run starts and read from 2 s
    later: the writes wait for the reader, so every line arrives (Python raised BlockingIOError,
    taken for a console gone, and under PYTHONUNBUFFERED dropped the text without a word)."""
    (tmp_path / "case.toml").write_text(TINY)
    read, write, filled = _full_pipe()
    env = {key: value for key, value in os.environ.items() if key != "PYTHONUNBUFFERED"}
    if unbuffered:
        env["PYTHONUNBUFFERED"] = "1"
    command = [sys.executable, "-m", "sphere_cli.cli", "run", "case.toml", "-o", "late"]
    proc = subprocess.Popen(command, cwd=tmp_path, stdout=write, stderr=write, env=env)
    os.close(write)
    time.sleep(2.0)
    with os.fdopen(read, "rb") as pipe:
        printed = pipe.read()[filled:].decode()
    assert proc.wait(timeout=600) == 0
    assert "[sphere] building the scene" in printed and "done: t = " in printed, printed
    assert "output: late/trajectory.h5" in printed, printed
    log = (tmp_path / "late" / "run.log").read_text()
    assert " is gone " not in log and "not being read" not in log, log


@pytest.mark.parametrize("unbuffered", [False, True], ids=["buffered", "unbuffered"])
def test_a_stalled_reader_is_waited_for_once_then_its_lines_dropped_until_it_reads(
    monkeypatch, caplog, unbuffered
):
    monkeypatch.setattr(console, "STALL_WAIT", 0.2)
    read, write, _ = _full_pipe()
    raw = io.FileIO(write, "w")
    # as Python makes stdout for a pipe: buffered, or unbuffered under PYTHONUNBUFFERED
    layer = raw if unbuffered else io.BufferedWriter(raw)
    text = io.TextIOWrapper(layer, write_through=unbuffered)
    stream = GuardedStream(text, "stdout")
    started = time.monotonic()
    stream.write("first\n")
    stream.flush()
    waited = time.monotonic() - started
    assert stream.stalled and not stream.gone and 0.2 <= waited < 5.0
    started = time.monotonic()
    stream.write("second\n")
    stream.flush()
    assert time.monotonic() - started < 0.1  # a stalled reader is not waited for again
    os.set_blocking(read, False)
    with pytest.raises(BlockingIOError):  # the reader comes back and empties the pipe
        while os.read(read, 65536):
            pass
    stream.write("third\n")
    stream.flush()
    assert not stream.stalled
    assert b"third\n" in os.read(read, 65536)
    stalls = [r.getMessage() for r in caplog.records if "not being read" in r.getMessage()]
    assert stalls == [
        "stdout is not being read (its pipe has been full for 0.2 s): what does not fit there is dropped "
        "until it is read again; run.log keeps the record"
    ]
    os.close(read)


def test_an_unbuffered_console_that_cannot_show_a_character_gets_it_replaced():
    """Under PYTHONUNBUFFERED the guard writes the bytes itself: the same replacement."""
    read, write = os.pipe()
    raw = io.FileIO(write, "w")
    stream = GuardedStream(io.TextIOWrapper(raw, encoding="latin-1", write_through=True), "stderr")
    stream.write("phi >= 0.61 \u2265 \u03c6\n")
    stream.write("next\n")
    raw.close()
    assert not stream.gone
    assert os.read(read, 100) == b"phi >= 0.61 ? ?\nnext\n"
    os.close(read)
