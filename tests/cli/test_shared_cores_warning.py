"""`sphere run` warns when its OpenMP threads would share their cores with other busy processes
(sphere_cli/runtime.py; the rules themselves: tests/unit/test_shared_cores.py)."""

from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest
from cli_test_support import TINY, edit, sphere_inproc


@pytest.mark.skipif(
    not os.path.exists("/proc/stat") or (os.cpu_count() or 1) < 2, reason="reads /proc/stat; needs 2 cores"
)
def test_sphere_run_warns_on_stderr_and_in_its_log(tmp_path, monkeypatch):
    """A 2-thread run started while every core is busy: the warning comes at once on stderr and
    stays in run.log; a command refused (a run directory that exists) gives only its error; with
    OMP_WAIT_POLICY=PASSIVE neither has it."""
    case = edit(TINY, "[simulation]\n", "[simulation]\nthreads = 2\n")
    case = edit(case, "duration = 0.002", "duration = 0.0002")
    (tmp_path / "case.toml").write_text(case)
    spin = "import time\nend = time.time() + 5\nwhile time.time() < end: pass\n"
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    monkeypatch.delenv("NUMBA_THREADING_LAYER", raising=False)
    children = [subprocess.Popen([sys.executable, "-c", spin]) for _ in range(os.cpu_count() or 1)]
    try:
        time.sleep(0.3)
        busy = sphere_inproc("run", "case.toml", "-o", "busy", "-q", cwd=tmp_path)
        refused = sphere_inproc("run", "case.toml", "-o", "busy", "-q", cwd=tmp_path)
    finally:
        for child in children:
            child.kill()
            child.wait()
    assert busy.code == 0, busy.stderr
    assert "sphere: warning: other processes keep" in busy.stderr
    assert "OMP_WAIT_POLICY=PASSIVE" in (tmp_path / "busy" / "run.log").read_text()
    assert refused.code != 0 and "sphere: error:" in refused.stderr
    assert "warning" not in refused.stderr

    monkeypatch.setenv("OMP_WAIT_POLICY", "PASSIVE")
    calm = sphere_inproc("run", "case.toml", "-o", "calm", "-q", cwd=tmp_path)
    assert calm.code == 0, calm.stderr
    assert "warning" not in calm.stderr
    assert "OMP_WAIT_POLICY" not in (tmp_path / "calm" / "run.log").read_text()
