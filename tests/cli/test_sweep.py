"""`sphere sweep`: ensembles of one case with keys varied, run as a SLURM job array or locally.

The values on the command line, the members' cases (checked before anything is written), the
job-array script (shellcheck, and bash running a task with a stand-in Python), a member that
requeues its own SLURM task, and a 6-member sweep run locally, killed (every process, as a node
failure would) and run again: it resumes, and a member that was cut off ends bitwise where an
uninterrupted run of its case ends. The summary table is checked against the trajectories as
h5py reads them.
"""

from __future__ import annotations

import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
import tomli
from cli_test_support import FROM_FILE, TINY, TWO_SPHERES_CSV, assert_clean_error, sphere_inproc

from sphere_cli import api
from sphere_cli import sweep as sweeps
from sphere_cli.errors import CaseError, ResumeRefused, StoppedEarly, UsageError
from sphere_cli.io.checkpoint import list_checkpoints, newest_valid_checkpoint, read_checkpoint
from sphere_cli.io.rundir import RunDirectory

SHELLCHECK = shutil.which("shellcheck") or str(Path(sys.executable).with_name("shellcheck"))


def test_vary_values_as_typed():
    assert sweeps.parse_vary("particles.seed=1..4") == sweeps.Vary("particles.seed", (1, 2, 3, 4))
    assert sweeps.parse_vary("contact.friction=0.3,0.5").values == (0.3, 0.5)
    assert sweeps.parse_vary("contact.model=hertz-mindlin,linear").values == ("hertz-mindlin", "linear")
    assert sweeps.parse_vary('contact.model="linear"').values == ("linear",)
    assert sweeps.parse_vary("domain.gravity=[0,0,-9.81],[0,0,-1.62]").values == (
        [0, 0, -9.81],
        [0, 0, -1.62],
    )
    assert sweeps.parse_vary("walls.0.velocity=[0,0,1]").parts == ("walls", 0, "velocity")
    # a bare word beside numbers: the word is a string, the numbers stay numbers (the time step
    # 1e-6 read as the string "1e-6" made that member fail its validation)
    assert sweeps.parse_vary("simulation.dt=auto,1e-6").values == ("auto", 1e-6)
    assert sweeps.parse_vary("walls.0.face=z+,2,true").values == ("z+", 2, True)
    for bad in ("particles.seed", "=1,2", "particles.seed=", "particles.seed=5..1", "a b=1", "x=1 2,(3)"):
        with pytest.raises(UsageError, match="--vary"):
            sweeps.parse_vary(bad)


def test_members_every_combination_or_zipped():
    a, b = sweeps.Vary("a", (1, 2, 3)), sweeps.Vary("b", (0.1, 0.2))
    assert sweeps.combinations([a, b], False) == [(1, 0.1), (1, 0.2), (2, 0.1), (2, 0.2), (3, 0.1), (3, 0.2)]
    assert sweeps.combinations([a, sweeps.Vary("c", (7, 8, 9))], True) == [(1, 7), (2, 8), (3, 9)]
    with pytest.raises(UsageError, match="a: 3, b: 2"):
        sweeps.combinations([a, b], True)
    assert sweeps.member_names(3) == ["m000", "m001", "m002"]
    assert sweeps.member_names(1001)[-1] == "m1000"


@pytest.fixture
def base(tmp_path) -> Path:
    case = tmp_path / "bed.toml"
    case.write_text(TINY)
    return case


def test_sweep_folder_and_member_cases(base, tmp_path):
    out = tmp_path / "sw"
    varies = [sweeps.parse_vary("particles.seed=1..3"), sweeps.parse_vary("contact.friction=0.3,0.5")]
    made = sweeps.create(base, varies, False, out)
    assert made.names == [f"m00{k}" for k in range(6)]
    table = (out / "members.csv").read_text().splitlines()
    assert table[0] == "member,particles.seed,contact.friction"
    assert table[4] == "m003,2,0.5"
    case = tomli.loads((out / "cases" / "m003.toml").read_text())
    assert case["particles"]["seed"] == 2 and case["contact"]["friction"] == 0.5
    # every other key as in the base case
    reference = tomli.loads(TINY)
    case["particles"].pop("seed"), case["contact"].pop("friction")
    assert case == reference
    manifest = json.loads((out / "sweep.json").read_text())
    assert manifest["members"][3] == {
        "name": "m003",
        "values": {"particles.seed": 2, "contact.friction": 0.5},
    }
    assert manifest["base_case"] == str(base.resolve())
    # the same sweep again: found as it is; another one in its folder: refused, members kept
    again = sweeps.create(base, varies, False, out)
    assert again.names == made.names
    # what an interrupted `sphere sweep` left (no sweep.json yet) is written over, cases too
    other = tmp_path / "left"
    (other / "cases").mkdir(parents=True)
    (other / "cases" / "m000.toml").write_text("# another sweep's member\n")
    sweeps.create(base, varies, False, other)
    assert tomli.loads((other / "cases" / "m000.toml").read_text())["contact"]["friction"] == 0.3
    with pytest.raises(ResumeRefused, match="vary"):
        sweeps.create(base, [sweeps.parse_vary("particles.seed=1..4")], False, out)
    assert (out / "cases" / "m005.toml").is_file()


@pytest.mark.parametrize(
    "vary, code, fragments",
    [
        ("contact.friction=0.5,-1", 65, ["sweep member m001", "contact.friction = -1", "contact.friction"]),
        ("contact.frictoin=0.5", 65, ["sweep member m000", "contact.frictoin"]),
        ("walls.3.face=z+", 2, ["walls has 1 entries", "index 3"]),
        ("particles.count.value=3", 2, ["particles.count is a value"]),
        ("contact.friction", 2, ["--vary 'contact.friction'", "KEY=VALUES"]),
        # a range typed with extra zeros: refused before its values are made (a hundred million
        # members were being checked in memory, for minutes, before a file was written)
        ("particles.seed=1..100000000", 2, ["100000000 values", "at most 100000 members"]),
    ],
)
def test_bad_sweep_is_refused_before_anything_is_written(base, tmp_path, vary, code, fragments):
    out = tmp_path / "sw"
    result = sphere_inproc("sweep", base, "--vary", vary, "-o", out)
    assert_clean_error(result, code, *fragments)
    assert not out.exists()


def test_a_product_of_ranges_beyond_the_members_limit_is_refused(base, tmp_path):
    out = tmp_path / "sw"
    result = sphere_inproc(
        "sweep", base, "--vary", "particles.seed=1..1000", "--vary", "particles.count=100..200", "-o", out
    )
    assert_clean_error(result, 2, "1000 (particles.seed) x 101 (particles.count) = 101000 members")
    assert not out.exists()


def test_sweep_folder_given_again_with_vary_is_a_usage_error(base, tmp_path):
    out = tmp_path / "sw"
    assert sphere_inproc("sweep", base, "--vary", "particles.seed=1,2", "-o", out).code == 0
    assert_clean_error(sphere_inproc("sweep", out, "--vary", "particles.seed=3"), 2, "is a sweep already")
    assert_clean_error(sphere_inproc("sweep-member", out, "7"), 2, "no member '7'", "m000..m001")
    assert_clean_error(sphere_inproc("sweep-summary", tmp_path), 66, "not a sweep directory")


def test_a_case_file_or_a_damaged_description_given_as_a_sweep_is_missing_input(base, tmp_path):
    """The base case given to sweep-summary, or a sweep.json that is not one sphere wrote: missing
    input (66, a file holding nothing usable), not an I/O failure (74, which a batch script may
    retry), saying which."""
    out = tmp_path / "sw"
    assert sphere_inproc("sweep", base, "--vary", "particles.seed=1,2", "-o", out).code == 0
    assert_clean_error(
        sphere_inproc("sweep-summary", base), 66, "a file, not the folder `sphere sweep` makes"
    )
    (out / "sweep.json").write_text("{ half a sweep")
    for command in ("sweep-summary", "sweep"):
        assert_clean_error(sphere_inproc(command, out), 66, "not a sweep description sphere wrote")


def test_members_read_relative_files_from_the_base_case_folder(tmp_path):
    """A placement file next to the base case is found by a member, though the members' cases
    live in the sweep's folder, and its run records the base case as the folder a resume resolves
    relative paths from; --zip pairs the values."""
    (tmp_path / "cases").mkdir()
    (tmp_path / "cases" / "pair.toml").write_text(FROM_FILE)
    (tmp_path / "cases" / "spheres.csv").write_text(TWO_SPHERES_CSV)
    out = tmp_path / "sw"
    made = sphere_inproc(
        "sweep", tmp_path / "cases" / "pair.toml", "-o", out, "--zip",
        "--vary", "contact.friction=0.2,0.4", "--vary", "particles.density=2000,3000",
    )  # fmt: skip
    assert made.code == 0, made.stderr
    assert (out / "members.csv").read_text().splitlines()[1:] == ["m000,0.2,2000", "m001,0.4,3000"]
    first = sphere_inproc("sweep-member", out, "1", "-q", "--max-wall-time", "0")
    assert first.code == 75, first.stderr  # stopped at once, a checkpoint written
    origin = RunDirectory(out / "runs" / "m001").case_origin()
    assert origin == (tmp_path / "cases" / "pair.toml").resolve()
    resumed = sphere_inproc("sweep-member", out, "1", "-q")
    assert resumed.code == 0, resumed.stderr
    assert sweeps.member_state(sweeps.Sweep.load(out), "m001")[0] == sweeps.DONE
    # a sweep's folder given to `inspect` says where the members are
    assert_clean_error(sphere_inproc("inspect", out), 66, "sphere sweep-summary", "runs/")


def test_members_sharing_a_placement_file_check_it_once_and_each_its_own(tmp_path, monkeypatch):
    """Each member's case is checked with its placement file (validate reads it), but a file the
    members share is read once: 9 members of a 300 000-sphere CSV took 17.1 s to write, 2.8 s
    now. A member whose own values put the file's spheres outside its box is still refused."""
    from sphere_cli.scene import builder

    (tmp_path / "pair.toml").write_text(FROM_FILE)
    (tmp_path / "spheres.csv").write_text(TWO_SPHERES_CSV)
    reads = []
    real = builder.read_particle_file

    def counted(placement, base_dir):
        reads.append(placement.path)
        return real(placement, base_dir)

    monkeypatch.setattr(builder, "read_particle_file", counted)
    sweeps.create(
        tmp_path / "pair.toml", [sweeps.parse_vary("particles.density=1000..1005")], False, tmp_path / "sw"
    )
    assert reads == ["spheres.csv"]
    narrow = sweeps.parse_vary("domain.upper=[0.01,0.01,0.01],[0.004,0.01,0.01]")
    with pytest.raises(CaseError, match=r"sweep member m001 .*outside the box along x"):
        sweeps.create(tmp_path / "pair.toml", [narrow], False, tmp_path / "sw2")
    assert reads == ["spheres.csv"] * 2


def test_job_array_script_passes_shellcheck_and_runs_its_task(base, tmp_path):
    out = tmp_path / "my 100% sweeps" / "sw"  # a space and sbatch's pattern character
    sweeps.create(base, [sweeps.parse_vary("particles.seed=1..5")], False, out, threads=4)
    script = out / "sweep.sbatch"
    text = script.read_text()
    assert "#SBATCH --array=0-4" in text and "#SBATCH --cpus-per-task=4" in text
    assert f'#SBATCH --output="{tmp_path}/my 100%% sweeps/sw/logs/%x-%A_%a.out"' in text
    checked = subprocess.run([SHELLCHECK, "--severity=style", str(script)], capture_output=True, text=True)
    assert checked.returncode == 0, checked.stdout
    # a task as SLURM starts it, with a stand-in for the Python that records what it is given
    stand_in = tmp_path / "python"
    stand_in.write_text('#!/bin/bash\necho "$NUMBA_NUM_THREADS $OMP_NUM_THREADS $*" > "$STUB_LOG"\n')
    stand_in.chmod(0o755)
    env = {
        **os.environ,
        "SLURM_ARRAY_TASK_ID": "3",
        "SLURM_CPUS_PER_TASK": "4",
        "SPHERE_PYTHON": str(stand_in),
    }
    env["STUB_LOG"] = str(tmp_path / "log")
    assert subprocess.run(["bash", str(script)], env=env).returncode == 0
    words = (tmp_path / "log").read_text().rstrip("\n").split(" ")
    assert " ".join(words[5:-3]) == str(out.resolve())
    assert words[:5] + words[-3:] == [
        "4",
        "4",
        "-m",
        "sphere_cli",
        "sweep-member",
        "3",
        "--requeue",
        "--quiet",
    ]
    # members beyond SLURM's array size limit: the same task ids with an offset; past the last
    # member a task ends at once
    subprocess.run(["bash", str(script)], env={**env, "SWEEP_OFFSET": "1"}, check=True)
    assert (tmp_path / "log").read_text().split()[-3] == "4"
    (tmp_path / "log").unlink()
    subprocess.run(["bash", str(script)], env={**env, "SWEEP_OFFSET": "1000"}, check=True)
    assert not (tmp_path / "log").exists()
    # outside a job array it says so, and starts nothing
    env.pop("SLURM_ARRAY_TASK_ID")
    refused = subprocess.run(["bash", str(script)], env=env, capture_output=True, text=True)
    assert refused.returncode != 0 and "sbatch" in refused.stderr and not (tmp_path / "log").exists()


def test_a_sweep_folder_sbatch_cannot_name_is_refused(base, tmp_path):
    result = sphere_inproc("sweep", base, "--vary", "particles.seed=1,2", "-o", tmp_path / "run#2")
    assert_clean_error(result, 2, "'#'", "#SBATCH")
    assert not (tmp_path / "run#2").exists()


def test_reading_a_run_directory_never_keeps_its_writer_out(tmp_path):
    """sweep-summary and --local probe each member's lock (RunDirectory.busy) while members start
    and resume: a probe must never make a writer's lock fail."""
    (tmp_path / "run").mkdir()
    writer, reader = RunDirectory(tmp_path / "run"), RunDirectory(tmp_path / "run")
    writer.lock()
    assert reader.busy()
    writer.unlock()
    assert not reader.busy()
    done = threading.Event()

    def probe():
        while not done.is_set():
            reader.busy()

    prober = threading.Thread(target=probe)
    prober.start()
    try:
        for _ in range(300):
            writer.lock()
            writer.unlock()
    finally:
        done.set()
        prober.join()


def test_the_users_slurm_template_passes_shellcheck():
    template = Path(__file__).parents[2] / "docs" / "slurm" / "sphere-job.sh"
    checked = subprocess.run([SHELLCHECK, "--severity=style", str(template)], capture_output=True, text=True)
    assert checked.returncode == 0, checked.stdout


@pytest.fixture
def scontrol(tmp_path, monkeypatch) -> Path:
    """A stand-in `scontrol` on PATH that records its arguments; SLURM's variables of array task
    77_4."""
    bin_dir = tmp_path / "bin"
    bin_dir.mkdir()
    log = tmp_path / "scontrol.log"
    (bin_dir / "scontrol").write_text(f'#!/bin/bash\necho "$@" >> {log}\n')
    (bin_dir / "scontrol").chmod(0o755)
    monkeypatch.setenv("PATH", f"{bin_dir}:{os.environ['PATH']}")
    for name, value in (("SLURM_JOB_ID", "80"), ("SLURM_ARRAY_JOB_ID", "77"), ("SLURM_ARRAY_TASK_ID", "4")):
        monkeypatch.setenv(name, value)
    return log


def test_member_stopped_before_its_time_limit_requeues_its_task(base, tmp_path, scontrol, monkeypatch):
    out = tmp_path / "sw"
    sweeps.create(base, [sweeps.parse_vary("particles.seed=1,2")], False, out)
    stopped = StoppedEarly("stopped early (SIGUSR1 received)", reason="SIGUSR1 received")

    def stop(*_args, **_kwargs):
        raise stopped

    real = sweeps.run_member
    monkeypatch.setattr(sweeps, "run_member", stop)
    result = sphere_inproc("sweep-member", out, "1", "--requeue", "-q")
    assert result.code == 0 and "requeued" in result.stderr
    assert scontrol.read_text() == "requeue 77_4\n"
    # scancel's SIGTERM: a checkpoint and exit 75, never a requeue
    stopped.reason = "SIGTERM received"
    assert sphere_inproc("sweep-member", out, "1", "--requeue", "-q").code == 75
    assert scontrol.read_text() == "requeue 77_4\n"
    # for real: the wall-time budget stops it and requeues; the next start finishes it; then nothing
    monkeypatch.setattr(sweeps, "run_member", real)
    result = sphere_inproc("sweep-member", out, "m001", "--requeue", "-q", "--max-wall-time", "0.1")
    assert result.code == 0 and "wall-time budget" in result.stderr
    assert scontrol.read_text() == "requeue 77_4\nrequeue 77_4\n"
    assert sweeps.member_state(sweeps.Sweep.load(out), "m001")[0] == sweeps.STOPPED
    assert sphere_inproc("sweep-member", out, "1", "--requeue", "-q").code == 0
    assert sweeps.member_state(sweeps.Sweep.load(out), "m001")[0] == sweeps.DONE
    again = sphere_inproc("sweep-member", out, "1", "--requeue", "-q")
    assert again.code == 0 and "done already" in again.stdout
    # a member whose integration failed is not run again: it would fail the same way
    status = out / "runs" / "m001" / "status.json"
    status.write_text(json.dumps({"state": "failed", "step": 9, "error": "blow-up at step 9"}))
    assert_clean_error(
        sphere_inproc("sweep-member", out, "1", "-q"), 70, "failed before", "blow-up", "remove"
    )
    failed = {"state": "failed", "step": 9, "error": "blow-up at step 9", "exit_code": 70}
    status.write_text(json.dumps(failed))
    assert sweeps.member_state(sweeps.Sweep.load(out), "m001")[0] == sweeps.FAILED
    # one stopped by its files (a full disk, exit 74) resumes from its checkpoint once they can be written
    status.write_text(json.dumps({**failed, "error": "trajectory.h5: no space left", "exit_code": 74}))
    assert sweeps.member_state(sweeps.Sweep.load(out), "m001")[0] == sweeps.INTERRUPTED
    assert sphere_inproc("sweep-member", out, "1", "-q").code == 0
    assert sweeps.member_state(sweeps.Sweep.load(out), "m001")[0] == sweeps.DONE


@pytest.mark.slow
def test_local_sweep_killed_resumes_and_sums_up(base, tmp_path):
    """Six members, two processes at a time. SIGTERM to the sweep once a member is under way: its
    running members checkpoint and it exits 75. Run again, then SIGKILL to the sweep and its
    members (a node failing): the member cut off is left interrupted. Run again: every member
    ends, from its checkpoints."""
    # fewer frames and checkpoints than TINY's one every 50 steps: writing them is most of a run
    text = TINY.replace("[output.frames]\nevery_steps = 50", "[output.frames]\nevery_steps = 500")
    base.write_text(
        text.replace("[output.checkpoints]\nevery_steps = 50", "[output.checkpoints]\nevery_steps = 100")
    )
    out = tmp_path / "sw"
    env = {**os.environ, "OMP_WAIT_POLICY": "PASSIVE"}
    sweep = [sys.executable, "-m", "sphere_cli", "sweep"]
    deadline = time.monotonic() + 180

    def start(*args) -> subprocess.Popen:
        command = [*sweep, *map(str, args), "--local", "2"]
        return subprocess.Popen(command, env=env, start_new_session=True, stdout=subprocess.DEVNULL)

    def under_way(skip=()) -> list[str]:
        """Members past a checkpoint at step 200 (one every 100 steps; about 1750 in all)."""
        if not (out / sweeps.SWEEP_FILE).is_file():
            return []
        names = [n for n in sweeps.Sweep.load(out).names if n not in skip]
        written = {n: list_checkpoints(out / "runs" / n / "checkpoints") for n in names}
        return [n for n, files in written.items() if files and int(files[-1].stem[5:]) >= 200]

    def settled(made) -> list[str]:
        # the members are not ours to wait for: their locks go when the kernel has closed their files
        while any(sweeps.member_state(made, n)[0] == sweeps.RUNNING for n in made.names):
            assert time.monotonic() < deadline
            time.sleep(0.05)
        return [sweeps.member_state(made, n)[0] for n in made.names]

    first = start(base, "-o", out, "--vary", "particles.seed=1..3", "--vary", "contact.friction=0.3,0.5")
    while not (going := under_way()):
        assert time.monotonic() < deadline and first.poll() is None
        time.sleep(0.05)
    first.send_signal(signal.SIGTERM)
    assert first.wait() == 75
    made = sweeps.Sweep.load(out)
    states = settled(made)
    assert states[made.names.index(going[0])] == sweeps.STOPPED, states  # it wrote a checkpoint
    started = [n for n, state in zip(made.names, states, strict=True) if state != sweeps.NOT_STARTED]

    second = start(out)
    while not (cut := under_way(skip=started)):
        assert time.monotonic() < deadline and second.poll() is None
        time.sleep(0.05)
    os.killpg(second.pid, signal.SIGKILL)
    second.wait()
    name = cut[0]
    assert settled(made)[made.names.index(name)] == sweeps.INTERRUPTED
    assert sweeps.DONE not in settled(made)[4:]
    again = subprocess.run([*sweep, str(out), "--local", "2"], env=env, capture_output=True, text=True)
    assert again.returncode == 0, again.stdout + again.stderr
    assert "6 members" in again.stdout
    assert "resuming from" in (out / "runs" / name / "run.log").read_text()
    # the member cut off ends bitwise where its case, run without a stop, ends
    whole = tmp_path / "whole"
    api.run(out / "cases" / f"{name}.toml", whole)
    resumed = read_checkpoint(newest_valid_checkpoint(out / "runs" / name / "checkpoints").path)
    uninterrupted = read_checkpoint(newest_valid_checkpoint(whole / "checkpoints").path)
    assert resumed.step == uninterrupted.step
    for key in ("pos", "vel", "angvel"):
        np.testing.assert_array_equal(
            resumed.arrays["particles"][key], uninterrupted.arrays["particles"][key]
        )
    # the summary: one row per member, its values, its state and its last observables
    with (out / "summary.csv").open() as table:
        rows = list(csv.DictReader(table))
    assert [row["member"] for row in rows] == made.names
    assert [row["state"] for row in rows] == ["done"] * 6
    assert [(row["particles.seed"], row["contact.friction"]) for row in rows][3] == ("2", "0.5")
    with h5py.File(out / "runs" / "m004" / "trajectory.h5", "r") as f:
        kinetic = f["observables/kinetic_energy/value"][-1]
        force = f["observables/wall_force/value"][-1]
    assert float(rows[4]["kinetic_energy"]) == kinetic
    assert float(rows[4]["wall_force[0][2]"]) == force[0, 2]
