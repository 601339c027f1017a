"""`sphere run` on cores that other busy processes keep: with no OMP_WAIT_POLICY its OpenMP
threads are made to wait passively, with the user's own policy it warns (sphere_cli/runtime.py;
the rules themselves: tests/unit/test_shared_cores.py). The runs are fresh processes, as a
user's are: OpenMP reads the policy when a process first starts its threads."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest
from cli_test_support import TINY, Result, edit

pytestmark = pytest.mark.skipif(
    not os.path.exists("/proc/stat") or (os.cpu_count() or 1) < 2, reason="reads /proc/stat; needs 2 cores"
)
SPIN = "while True: pass\n"


def _beside_busy_cores(*args, cwd) -> Result:
    """`sphere ARGS` started while a spinning process holds every core; the spinners end at the
    command's first line on stderr (the sample of the cores is over by then) or at its end."""
    spinners = [subprocess.Popen([sys.executable, "-c", SPIN]) for _ in range(os.cpu_count() or 1)]
    try:
        time.sleep(0.3)  # let them start
        proc = subprocess.Popen(
            [sys.executable, "-m", "sphere_cli.cli", *map(str, args)],
            cwd=cwd,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        first = proc.stderr.readline()
    finally:
        for spinner in spinners:
            spinner.kill()
            spinner.wait()
    stdout, rest = proc.communicate(timeout=600)
    return Result(proc.returncode, stdout, first + rest)


@pytest.fixture
def case(tmp_path, monkeypatch):
    text = edit(TINY, "[simulation]\n", "[simulation]\nthreads = 2\n")
    (tmp_path / "case.toml").write_text(edit(text, "duration = 0.002", "duration = 0.0002"))
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    monkeypatch.delenv("NUMBA_THREADING_LAYER", raising=False)
    return tmp_path


def test_threads_on_busy_cores_wait_passively_when_no_policy_is_chosen(case):
    """The note comes at once on stderr and stays in run.log; a command refused (a run directory
    that exists) gives only its error."""
    run = _beside_busy_cores("run", "case.toml", "-o", "busy", "-q", cwd=case)
    refused = _beside_busy_cores("run", "case.toml", "-o", "busy", "-q", cwd=case)
    assert run.code == 0, run.stderr
    assert run.stderr.startswith("sphere: note: other processes keep"), run.stderr
    assert "wait passively (OMP_WAIT_POLICY=PASSIVE)" in run.stderr and "warning" not in run.stderr
    assert "wait passively (OMP_WAIT_POLICY=PASSIVE)" in (case / "busy" / "run.log").read_text()
    assert refused.code != 0 and refused.stderr.startswith("sphere: error:"), refused.stderr
    assert "note" not in refused.stderr


def test_a_chosen_policy_is_kept_and_warned_of_or_quiet(case, monkeypatch):
    """OMP_WAIT_POLICY=ACTIVE on busy cores: kept, with the warning on stderr and in run.log;
    OMP_WAIT_POLICY=PASSIVE: neither note nor warning."""
    monkeypatch.setenv("OMP_WAIT_POLICY", "ACTIVE")
    active = _beside_busy_cores("run", "case.toml", "-o", "active", "-q", cwd=case)
    assert active.code == 0, active.stderr
    assert active.stderr.startswith("sphere: warning: other processes keep"), active.stderr
    assert "set OMP_WAIT_POLICY=PASSIVE" in (case / "active" / "run.log").read_text()

    monkeypatch.setenv("OMP_WAIT_POLICY", "PASSIVE")
    calm = _beside_busy_cores("run", "case.toml", "-o", "calm", "-q", cwd=case)
    assert calm.code == 0, calm.stderr
    assert "sphere: note" not in calm.stderr and "sphere: warning" not in calm.stderr, calm.stderr
    assert "OMP_WAIT_POLICY" not in (case / "calm" / "run.log").read_text()
