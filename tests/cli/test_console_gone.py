"""A console that goes away does not end a run (sphere_cli/io/console.py): `sphere run case.toml
| head` whose reader exits, a `tee` that dies. The run is a real process whose stdout and stderr
are pipes closed before it prints anything; it must end as a run with its console does, with the
loss noted in run.log."""

from __future__ import annotations

import json
import subprocess
import sys

import h5py
import numpy as np
from cli_test_support import TINY, TINY_END_STEP

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
