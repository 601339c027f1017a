"""Restart is bitwise: a run stopped and resumed ends in exactly the state of an uninterrupted run.

Checked for every example case in configs/ (shortened to a few hundred steps), and for a run
killed (SIGKILL) in the middle of writing a checkpoint: the previous checkpoint stays valid
and the resumed run still matches the uninterrupted one bit for bit.
"""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import h5py
import numpy as np
import pytest
from restart_support import CASE, assert_same_state, final_state, frames, step_dt

from sphere_cli import api
from sphere_cli.config.load import load_case
from sphere_cli.errors import ResumeRefused
from sphere_cli.io.checkpoint import FORMAT, list_checkpoints, read_checkpoint
from sphere_cli.io.inspect import summarize
from sphere_cli.scene.builder import build_scene

CONFIGS = sorted((Path(__file__).parents[2] / "configs").glob("*.toml"))
STEPS = 240


@pytest.mark.parametrize("config", CONFIGS, ids=[c.stem for c in CONFIGS])
def test_resume_is_bitwise_identical(config: Path, tmp_path: Path):
    dt = step_dt(config)
    end = STEPS * dt
    whole = api.run(config, tmp_path / "whole", until=end)
    api.run(config, tmp_path / "split", until=0.5 * end)
    split = api.resume(tmp_path / "split", until=end)
    assert whole.step == split.step == STEPS
    assert_same_state(final_state(tmp_path / "whole"), final_state(tmp_path / "split"))
    a, b = frames(tmp_path / "whole"), frames(tmp_path / "split")
    for step in a.keys() & b.keys():
        assert np.array_equal(a[step], b[step])
    assert a.keys() <= b.keys()


def test_the_energy_budget_resumes_bitwise(tmp_path: Path):
    """The budget's checkpoint holds each particle's share of its terms: a run resumed halfway
    ends with the uninterrupted run's shares and observables, bit for bit."""
    case = tmp_path / "case.toml"
    text = textwrap.dedent(CASE.format(duration=1.0))
    case.write_text(text + '[output.observables]\nquantities = ["energy_budget"]\nevery_steps = 60\n')
    end = STEPS * step_dt(case)
    api.run(case, tmp_path / "whole", until=end)
    api.run(case, tmp_path / "split", until=0.5 * end)
    api.resume(tmp_path / "split", until=end)
    a, b = final_state(tmp_path / "whole"), final_state(tmp_path / "split")
    assert_same_state(a, b)
    assert a["energy_budget"]["booked"].any()
    with (
        h5py.File(tmp_path / "whole" / "trajectory.h5") as w,
        h5py.File(tmp_path / "split" / "trajectory.h5") as s,
    ):
        for name in ("work_gravity", "dissipated_damping", "energy_balance_residual"):
            series = f"observables/{name}/value"
            assert np.array_equal(w[series][-1], s[series][-1]), name


def test_vans1d_turbulent_fluctuations_resume_bitwise(tmp_path: Path):
    """configs/bedload.toml with [fluid.fluctuations]: the fluctuations, their lifetimes and
    each particle's count of draws are in the checkpoint, so a resume (here between two fluid
    couplings) continues every particle's random sequence exactly."""
    config = Path(__file__).parents[2] / "configs" / "bedload.toml"
    text = config.read_text().replace(
        "flow = {", "fluctuations = { bed_elevation = 0.034, seed = 3 }\nflow = {", 1
    )
    case = tmp_path / "bedload.toml"
    case.write_text(text)
    (tmp_path / "bedload-bed.csv").write_bytes((config.parent / "bedload-bed.csv").read_bytes())
    dt = step_dt(case)
    end = STEPS * dt
    api.run(case, tmp_path / "whole", until=end)
    api.run(case, tmp_path / "split", until=0.5 * end)
    api.resume(tmp_path / "split", until=end)
    whole = final_state(tmp_path / "whole")
    assert_same_state(whole, final_state(tmp_path / "split"))
    assert np.count_nonzero(whole["fluid"]["fluctuation"][:, 2]) > 10  # the beads above the bed
    assert whole["fluid"]["fluctuation_draws"].max() >= 1


# Runs the case in a child process that SIGKILLs itself while writing the checkpoint of step
# 300: after `part` of its bytes are on disk (the file is built in memory, then written), or
# just before the rename.
KILLER = """
import os, signal, sys
from sphere_cli.io import checkpoint

target, part = int(sys.argv[3]), float(sys.argv[4])
original_write = checkpoint.write_file
original_publish = checkpoint.publish

def write_file(path, data):
    if f"{target:012d}" in path.name and part:
        original_write(path, data[: int(part * len(data))])
        os.kill(os.getpid(), signal.SIGKILL)
    original_write(path, data)

def publish(tmp, final):
    if f"{target:012d}" in final.name and not part:
        os.kill(os.getpid(), signal.SIGKILL)
    original_publish(tmp, final)

checkpoint.write_file = write_file
checkpoint.publish = publish
from sphere_cli import api
from sphere_cli.scene.builder import build_scene
from sphere_cli.config.load import load_case
api.run(sys.argv[1], sys.argv[2])
"""


@pytest.mark.parametrize("part", [0, 0.6], ids=["before-rename", "mid-write"])
def test_kill_during_checkpoint_write(tmp_path: Path, part: float):
    dt_case = tmp_path / "probe.toml"
    dt_case.write_text(textwrap.dedent(CASE.format(duration=1.0)))
    dt = step_dt(dt_case)
    case = tmp_path / "case.toml"
    case.write_text(textwrap.dedent(CASE.format(duration=repr(400 * dt))))
    api.run(case, tmp_path / "whole")

    script = tmp_path / "killer.py"
    script.write_text(KILLER)
    child = subprocess.run(
        [sys.executable, str(script), str(case), str(tmp_path / "killed"), "300", str(part)],
        capture_output=True,
        text=True,
        env=os.environ.copy(),
    )
    assert child.returncode == -9, child.stderr
    ckpts = list_checkpoints(tmp_path / "killed" / "checkpoints")
    assert [int(p.stem.split("-")[1]) for p in ckpts] == [0, 100, 200]
    read_checkpoint(ckpts[-1])  # the newest checkpoint verifies
    # its status says it was running (from its first steps on); inspect adds that no process
    # holds it any more, and how to go on
    status = summarize(tmp_path / "killed")["status"]
    assert status["state"] == "running" and status["step"] >= 1, status
    assert status["writer"].startswith("gone: no process holds the run"), status

    result = api.resume(tmp_path / "killed")
    assert result.step == 400
    assert "writer" not in summarize(tmp_path / "killed")["status"]
    assert_same_state(final_state(tmp_path / "whole"), final_state(tmp_path / "killed"))
    assert not list((tmp_path / "killed" / "checkpoints").glob(".*.tmp"))


def test_changed_skin_on_resume_is_still_bitwise(tmp_path: Path):
    """neighbor_skin may change on resume: the list is rebuilt, and the result is unchanged."""
    dense = 'density = 2500.0\nplacement = {{ method = "lattice", spacing = 1.0, jitter = 0.5 }}\n'
    low = CASE.replace("count = 40", "count = 100").replace(
        "density = 2500.0", dense + "velocity = [0.05, 0.0, -0.1]"
    )
    probe = tmp_path / "probe.toml"
    probe.write_text(textwrap.dedent(low.format(duration=1.0)))
    dt = step_dt(probe)
    case = tmp_path / "case.toml"
    case.write_text(textwrap.dedent(low.format(duration=repr(4000 * dt))))  # the bed has landed
    api.run(case, tmp_path / "whole")
    api.run(case, tmp_path / "split", until=2500 * dt)
    edited = tmp_path / "split" / "case.toml"
    edited.write_text(edited.read_text().replace("[simulation]", "[simulation]\nneighbor_skin = 1.5"))
    api.resume(tmp_path / "split")
    whole, split = final_state(tmp_path / "whole"), final_state(tmp_path / "split")
    for module in ("particles", "walls"):
        for name in whole[module]:
            assert np.array_equal(whole[module][name], split[module][name]), f"{module}/{name}"
    assert _pair_history(whole["neighbors"]) == _pair_history(split["neighbors"])


HERTZ_CASE = """
    [simulation]
    duration = {duration}
    dt = {dt}
    stability = "contact"
    [domain]
    upper = [0.008, 0.008, 0.02]
    [particles]
    count = 100
    material = {{ soft = 0.6, hard = 0.4 }}
    radius = {{ distribution = "uniform", min = 0.0007, max = 0.0009 }}
    placement = {{ method = "lattice", spacing = 1.0 }}
    velocity = [0.05, 0.0, -0.2]
    [contact]
    model = "hertz-mindlin"
    rolling_friction = 0.05
    [[contact.pairs]]
    materials = ["soft", "hard"]
    restitution = 0.3
    [[materials]]
    name = "soft"
    density = 1200.0
    youngs_modulus = 1.0e7
    poisson_ratio = 0.4
    [[materials]]
    name = "hard"
    density = 2500.0
    youngs_modulus = 5.0e7
    poisson_ratio = 0.25
    [[walls]]
    face = "z-"
    material = "hard"
    [[walls]]
    face = "x-"
    [output.frames]
    every_steps = 500
    [output.checkpoints]
    every_steps = 1000
"""


def test_hertz_mixture_with_contacts_resumes_bitwise(tmp_path: Path):
    """Hertz-Mindlin, two materials (the material ids are restored from the checkpoint, not drawn
    again), a pair table, a wall material and rolling resistance, stopped while many contacts
    carry tangential springs: the resumed run ends bitwise equal to the uninterrupted one."""
    probe = tmp_path / "probe.toml"
    probe.write_text(textwrap.dedent(HERTZ_CASE.format(duration=1.0, dt='"auto"')))
    # a tenth of the limit of one contact: contacts form within the 4500 steps (dt = "auto",
    # below the bound for many contacts at once, would need ~4 times as many)
    dt = 0.1 * build_scene(load_case(probe)).dt_limit
    case = tmp_path / "case.toml"
    case.write_text(textwrap.dedent(HERTZ_CASE.format(duration=repr(6000 * dt), dt=repr(dt))))
    api.run(case, tmp_path / "whole")
    api.run(case, tmp_path / "split", until=4500 * dt)
    middle = final_state(tmp_path / "split")
    assert set(middle["particles"]["material"]) == {0, 1}
    with h5py.File(tmp_path / "split" / "trajectory.h5", "r") as f:  # H5MD species = material id
        species = f["particles/trajectory/species"]
        assert np.array_equal(species[...], middle["particles"]["material"])
        assert [name.decode() for name in species.attrs["materials"]] == ["soft", "hard"]
    assert np.count_nonzero(middle["neighbors"]["hist"]) > 40  # springs in play at the stop
    assert np.count_nonzero(middle["walls"]["hist"]) > 4
    api.resume(tmp_path / "split")
    whole, split = final_state(tmp_path / "whole"), final_state(tmp_path / "split")
    for module in ("particles", "walls"):
        for name in whole[module]:
            assert np.array_equal(whole[module][name], split[module][name]), f"{module}/{name}"
    # The neighbour list's slots past nbr_count are not state: the list is built into a double
    # buffer whose unused slots keep entries of an older build (fresh zeros after a restore),
    # so only the listed pairs are compared, in order.
    assert np.array_equal(whole["neighbors"]["nbr_count"], split["neighbors"]["nbr_count"])
    assert np.array_equal(whole["neighbors"]["ref_pos"], split["neighbors"]["ref_pos"])
    assert _listed(whole["neighbors"]) == _listed(split["neighbors"])


def _listed(nl: dict) -> list:
    """Every particle's listed neighbours with their springs, in list order."""
    rows = []
    for i in range(nl["nbr"].shape[0]):
        count = min(nl["nbr_count"][i], nl["nbr"].shape[1])
        rows.append((nl["nbr"][i, :count].tolist(), nl["hist"][i, :count].tolist()))
    return rows


def _pair_history(nl: dict) -> dict:
    """(i, j) -> tangential spring, for every listed pair with a spring (the lists differ)."""
    springs = {}
    for i in range(nl["nbr"].shape[0]):
        for k in range(min(nl["nbr_count"][i], nl["nbr"].shape[1])):
            if np.any(nl["hist"][i, k] != 0):
                springs[(i, int(nl["nbr"][i, k]))] = tuple(nl["hist"][i, k])
    assert springs, "the test scene should have contacts with history"
    return springs


def test_changed_output_fields_refused(tmp_path: Path):
    case = tmp_path / "case.toml"
    case.write_text(textwrap.dedent(CASE.format(duration=1e-3)))
    api.run(case, tmp_path / "run")
    edited = tmp_path / "run" / "case.toml"
    edited.write_text(
        edited.read_text().replace("[output.frames]", '[output]\nfields = ["torque"]\n[output.frames]')
    )
    with pytest.raises(ResumeRefused, match="output.fields"):
        api.resume(tmp_path / "run", until=2e-3)


def test_a_checkpoint_of_an_older_format_is_refused(tmp_path: Path):
    """Checkpoints of another layout (format 2 named the fluid state phi/beta and kept all-zero
    springs) are not read as if they were this one's, nor skipped for an older checkpoint: the
    reader refuses the resume (exit 78) naming both formats."""
    case = tmp_path / "case.toml"
    case.write_text(textwrap.dedent(CASE.format(duration=0.002)))
    api.run(case, tmp_path / "run", until=200 * step_dt(case))
    newest = list_checkpoints(tmp_path / "run" / "checkpoints")[-1]
    with h5py.File(newest, "r+") as f:
        f.attrs["format"] = 2
    with pytest.raises(ResumeRefused, match=f"checkpoint format 2, this version reads format {FORMAT}"):
        read_checkpoint(newest)
