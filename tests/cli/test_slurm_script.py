"""docs/slurm/sphere-job.sh, the SLURM template of the user guide, run by bash with stand-ins for
`sphere`, `scontrol` and `sbatch` on PATH (no SLURM controller here): SIGUSR1 before the time limit
requeues and ends the segment with exit 0 (sacct: REQUEUED, not FAILED); scancel's SIGTERM
checkpoints and ends the chain; the fallback resubmission of an array task runs its own seeded
case in its own run directory, never a second nested member. And the other batch setting a
user meets first: `make demo`'s OpenMP wait policy.
"""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import pytest

SCRIPT = Path(__file__).parents[2] / "docs" / "slurm" / "sphere-job.sh"

# `sphere`: records its arguments; with STUB_WAIT it runs until SIGUSR1 and then exits 75, as
# sphere does after writing its checkpoint
SPHERE = """#!/bin/bash
echo "$@" >> "$STUB_LOG/sphere"
if [ -n "${STUB_WAIT:-}" ]; then
    trap 'exit 75' USR1
    while :; do sleep 0.05; done
fi
exit 0
"""
SCONTROL = """#!/bin/bash
echo "$@" >> "$STUB_LOG/scontrol"
if [ "$1" = show ]; then echo "   Command=$STUB_SCRIPT"; exit 0; fi
exit "${STUB_REQUEUE_RC:-0}"
"""
SBATCH = """#!/bin/bash
echo "args $*" >> "$STUB_LOG/sbatch"
echo "array_task=${SLURM_ARRAY_TASK_ID:-unset} seeded=${SPHERE_SEEDED:-unset}" >> "$STUB_LOG/sbatch"
"""


@pytest.fixture
def job(tmp_path):
    """(run the script with extra env vars, the folder of the stand-ins' logs)."""
    bin_dir, logs = tmp_path / "bin", tmp_path / "logs"
    bin_dir.mkdir()
    logs.mkdir()
    for name, text in (("sphere", SPHERE), ("scontrol", SCONTROL), ("sbatch", SBATCH)):
        (bin_dir / name).write_text(text)
        (bin_dir / name).chmod(0o755)
    cases = tmp_path / "cases"
    cases.mkdir()
    (cases / "bed.toml").write_text("[particles]\nseed = 1\ncount = 10\n")

    def start(**env) -> subprocess.Popen:
        full = {
            **{k: v for k, v in os.environ.items() if not k.startswith("SLURM_")},
            "PATH": f"{bin_dir}:{os.environ['PATH']}",
            "STUB_LOG": str(logs),
            "STUB_SCRIPT": str(SCRIPT),
            "CASE": "cases/bed.toml",
            "SLURM_JOB_ID": "7",
            **env,
        }
        return subprocess.Popen(
            ["bash", str(SCRIPT)], cwd=tmp_path, env=full, stdout=subprocess.PIPE, text=True
        )

    return start, logs


def _signal_when_running(proc: subprocess.Popen, logs: Path, signum: int) -> int:
    deadline = time.monotonic() + 30
    while not (logs / "sphere").exists():
        assert time.monotonic() < deadline and proc.poll() is None, "sphere never started"
        time.sleep(0.02)
    time.sleep(0.3)  # the script's traps are set right after it starts sphere
    proc.send_signal(signum)
    proc.communicate(timeout=30)
    return proc.returncode


def _log(logs: Path, name: str) -> str:
    path = logs / name
    return path.read_text() if path.exists() else ""


def test_the_time_limit_signal_requeues_and_the_segment_ends_well(job):
    start, logs = job
    rc = _signal_when_running(start(STUB_WAIT="1"), logs, signal.SIGUSR1)
    assert rc == 0  # sacct shows the segment as requeued, not as failed with 75
    assert "requeue 7" in _log(logs, "scontrol")
    assert _log(logs, "sphere").split() == ["run", "cases/bed.toml", "-o", "runs/bed"]


def test_scancel_checkpoints_and_ends_the_chain(job):
    start, logs = job
    rc = _signal_when_running(start(STUB_WAIT="1"), logs, signal.SIGTERM)
    assert rc == 75  # stopped with a checkpoint
    assert "requeue" not in _log(logs, "scontrol") and not _log(logs, "sbatch")


def test_the_fallback_resubmission_of_an_array_task_is_not_seeded_again(job, tmp_path):
    start, logs = job
    array = {"SLURM_ARRAY_TASK_ID": "3", "SLURM_ARRAY_JOB_ID": "5"}
    rc = _signal_when_running(start(STUB_WAIT="1", STUB_REQUEUE_RC="1", **array), logs, signal.SIGUSR1)
    assert rc == 0
    assert "requeue 5_3" in _log(logs, "scontrol")
    sbatch = _log(logs, "sbatch")
    assert "CASE=cases/bed-seed3.toml,RUN_DIR=runs/bed-seed3," in sbatch and "SPHERE_SEEDED=1" in sbatch
    assert "array_task=unset seeded=1" in sbatch
    assert (tmp_path / "cases" / "bed-seed3.toml").read_text().startswith("[particles]\nseed = 3\n")
    # the resubmitted job, even were an array variable to leak into it, runs the same member
    (logs / "sphere").unlink()
    resubmitted = start(CASE="cases/bed-seed3.toml", RUN_DIR="runs/bed-seed3", SPHERE_SEEDED="1", **array)
    resubmitted.communicate(timeout=30)
    assert resubmitted.returncode == 0
    assert _log(logs, "sphere").split() == ["run", "cases/bed-seed3.toml", "-o", "runs/bed-seed3"]
    assert not (tmp_path / "cases" / "bed-seed3-seed3.toml").exists()


def test_make_demo_leaves_the_wait_policy_to_sphere():
    """`make demo` sets no OMP_WAIT_POLICY of its own: sphere chooses from the cores' load at the
    start (passive where other processes keep them busy: tests/cli/test_shared_cores_warning.py),
    and one the user exports reaches it unchanged. Forcing PASSIVE made it 6.6 x slower on free
    cores; forcing spinning, 20 x slower on a shared machine."""
    root = SCRIPT.parents[2]
    recipe = subprocess.run(["make", "-n", "demo"], cwd=root, capture_output=True, text=True)
    assert recipe.returncode == 0, recipe.stderr
    run = next(line for line in recipe.stdout.splitlines() if "sphere run configs/demo.toml" in line)
    assert run.split(" ")[0].endswith("/sphere"), run
    assert "OMP_WAIT_POLICY" not in recipe.stdout, recipe.stdout
