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

from sphere_cli import api
from sphere_cli.build.scene import build_scene
from sphere_cli.config.load import load_case
from sphere_cli.errors import ResumeRefused
from sphere_cli.io.checkpoint import list_checkpoints, read_checkpoint

CONFIGS = sorted((Path(__file__).parents[2] / "configs").glob("*.toml"))
STEPS = 240


def _dt(case_path: Path) -> float:
    return build_scene(load_case(case_path)).state.clock.dt


def _final_state(run_dir: Path) -> dict:
    return read_checkpoint(list_checkpoints(run_dir / "checkpoints")[-1]).arrays


def _assert_same_state(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for module in a:
        assert a[module].keys() == b[module].keys()
        for name in a[module]:
            assert np.array_equal(a[module][name], b[module][name]), f"{module}/{name} differs"


def _frames(run_dir: Path) -> dict[int, np.ndarray]:
    with h5py.File(run_dir / "trajectory.h5", "r") as f:
        g = f["particles/trajectory/position"]
        return {int(s): v for s, v in zip(g["step"][...], g["value"][...], strict=True)}


@pytest.mark.parametrize("config", CONFIGS, ids=[c.stem for c in CONFIGS])
def test_resume_is_bitwise_identical(config: Path, tmp_path: Path):
    dt = _dt(config)
    end = STEPS * dt
    whole = api.run(config, tmp_path / "whole", until=end)
    api.run(config, tmp_path / "split", until=0.5 * end)
    split = api.resume(tmp_path / "split", until=end)
    assert whole.step == split.step == STEPS
    _assert_same_state(_final_state(tmp_path / "whole"), _final_state(tmp_path / "split"))
    a, b = _frames(tmp_path / "whole"), _frames(tmp_path / "split")
    for step in a.keys() & b.keys():
        assert np.array_equal(a[step], b[step])
    assert a.keys() <= b.keys()


CASE = """
    [simulation]
    duration = {duration}
    [domain]
    upper = [0.01, 0.01, 0.02]
    [particles]
    count = 40
    density = 2500.0
    radius = {{ distribution = "uniform", min = 0.0007, max = 0.0009 }}
    [contact]
    model = "linear"
    normal_stiffness = 1.0e4
    [[walls]]
    face = "z-"
    [output.frames]
    every_steps = 50
    [output.checkpoints]
    every_steps = 100
    keep = 3
"""

# Runs the case in a child process that SIGKILLs itself while writing the checkpoint of step
# 300: after `datasets` arrays of that checkpoint are on disk, or just before the rename.
KILLER = """
import os, signal, sys
import h5py
from sphere_cli import api
from sphere_cli.io import checkpoint

target, datasets = int(sys.argv[3]), int(sys.argv[4])
original_create = h5py.Group.create_dataset
original_publish = checkpoint.publish
written = [0]

def create_dataset(self, name, *args, **kwargs):
    if f"{target:012d}" in self.file.filename:
        written[0] += 1
        if datasets and written[0] > datasets:
            os.kill(os.getpid(), signal.SIGKILL)
    return original_create(self, name, *args, **kwargs)

def publish(tmp, final):
    if f"{target:012d}" in final.name and not datasets:
        os.kill(os.getpid(), signal.SIGKILL)
    original_publish(tmp, final)

h5py.Group.create_dataset = create_dataset
checkpoint.publish = publish
api.run(sys.argv[1], sys.argv[2])
"""


@pytest.mark.parametrize("datasets", [0, 3], ids=["before-rename", "mid-write"])
def test_kill_during_checkpoint_write(tmp_path: Path, datasets: int):
    dt_case = tmp_path / "probe.toml"
    dt_case.write_text(textwrap.dedent(CASE.format(duration=1.0)))
    dt = _dt(dt_case)
    case = tmp_path / "case.toml"
    case.write_text(textwrap.dedent(CASE.format(duration=repr(400 * dt))))
    api.run(case, tmp_path / "whole")

    script = tmp_path / "killer.py"
    script.write_text(KILLER)
    child = subprocess.run(
        [sys.executable, str(script), str(case), str(tmp_path / "killed"), "300", str(datasets)],
        capture_output=True,
        text=True,
        env=os.environ.copy(),
    )
    assert child.returncode == -9, child.stderr
    ckpts = list_checkpoints(tmp_path / "killed" / "checkpoints")
    assert [int(p.stem.split("-")[1]) for p in ckpts] == [0, 100, 200]
    read_checkpoint(ckpts[-1])  # the newest checkpoint verifies

    result = api.resume(tmp_path / "killed")
    assert result.step == 400
    _assert_same_state(_final_state(tmp_path / "whole"), _final_state(tmp_path / "killed"))
    assert not list((tmp_path / "killed" / "checkpoints").glob(".*.tmp"))


def test_changed_skin_on_resume_is_still_bitwise(tmp_path: Path):
    """neighbor_skin may change on resume: the list is rebuilt, and the result is unchanged."""
    dense = 'density = 2500.0\nplacement = {{ method = "lattice", spacing = 1.0, jitter = 0.5 }}\n'
    low = CASE.replace("count = 40", "count = 100").replace(
        "density = 2500.0", dense + "velocity = [0.05, 0.0, -0.1]"
    )
    probe = tmp_path / "probe.toml"
    probe.write_text(textwrap.dedent(low.format(duration=1.0)))
    dt = _dt(probe)
    case = tmp_path / "case.toml"
    case.write_text(textwrap.dedent(low.format(duration=repr(4000 * dt))))  # the bed has landed
    api.run(case, tmp_path / "whole")
    api.run(case, tmp_path / "split", until=2500 * dt)
    edited = tmp_path / "split" / "case.toml"
    edited.write_text(edited.read_text().replace("[simulation]", "[simulation]\nneighbor_skin = 1.5"))
    api.resume(tmp_path / "split")
    whole, split = _final_state(tmp_path / "whole"), _final_state(tmp_path / "split")
    for module in ("particles", "walls"):
        for name in whole[module]:
            assert np.array_equal(whole[module][name], split[module][name]), f"{module}/{name}"
    assert _pair_history(whole["neighbors"]) == _pair_history(split["neighbors"])


HERTZ_CASE = """
    [simulation]
    duration = {duration}
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
    probe.write_text(textwrap.dedent(HERTZ_CASE.format(duration=1.0)))
    dt = _dt(probe)
    case = tmp_path / "case.toml"
    case.write_text(textwrap.dedent(HERTZ_CASE.format(duration=repr(6000 * dt))))
    api.run(case, tmp_path / "whole")
    api.run(case, tmp_path / "split", until=4500 * dt)
    middle = _final_state(tmp_path / "split")
    assert set(middle["particles"]["material"]) == {0, 1}
    with h5py.File(tmp_path / "split" / "trajectory.h5", "r") as f:  # H5MD species = material id
        species = f["particles/trajectory/species"]
        assert np.array_equal(species[...], middle["particles"]["material"])
        assert [name.decode() for name in species.attrs["materials"]] == ["soft", "hard"]
    assert np.count_nonzero(middle["neighbors"]["hist"]) > 40  # springs in play at the stop
    assert np.count_nonzero(middle["walls"]["hist"]) > 4
    api.resume(tmp_path / "split")
    whole, split = _final_state(tmp_path / "whole"), _final_state(tmp_path / "split")
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
