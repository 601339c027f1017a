"""Chained stages resume bitwise: a run stopped inside any stage and resumed ends in exactly the
state of the uninterrupted run (the checkpoint holds the stage index, its first step, the wall
positions then, and the walls' motion).

The case exercises every stop path and the moving parts: a deposit stage ended by its
kinetic-energy test, a stress-controlled top wall that approaches the bed, then shears it at a
prescribed velocity until a shear displacement is reached; a rough floor and a fixed group.
"""

from __future__ import annotations

import h5py
import numpy as np
import pytest

from sphere_cli import api
from sphere_cli.io.checkpoint import list_checkpoints, read_checkpoint

CASE = """
[simulation]
duration = 0.01
threads = 1
[domain]
upper = [0.008, 0.008, 0.012]
periodic = [true, false, false]
[particles]
count = 30
density = 2500.0
seed = 1
radius = { distribution = "uniform", min = 0.0008, max = 0.001 }
placement = { method = "lattice", spacing = 1.05, region_lower = [0.0, 0.0, 0.0011] }
[[particles.groups]]
region_lower = [0.0, 0.0, 0.0]
region_upper = [0.008, 0.002, 0.0035]
motion = "fixed"
[contact]
model = "linear"
normal_stiffness = 1.0e4
[[walls]]
face = "z-"
rough = { spacing = 1.2 }
[[walls]]
face = "z+"
[[walls]]
face = "y-"
[[walls]]
face = "y+"
mode = "stress"
stress = 50.0
[[stages]]
name = "deposit"
duration = 0.004
stop_when = { kinetic_energy_below = 1.0, min_time = 0.0003 }
check_every = 25
[[stages]]
name = "load"
duration = 0.0004
friction = 0.2
[[stages.walls]]
face = "z+"
mode = "stress"
stress = 500.0
approach = true
[[stages]]
name = "shear"
duration = 0.004
stop_when = { wall = "z+", shear_displacement = 3e-5 }
check_every = 10
[[stages.walls]]
face = "z+"
mode = "stress"
stress = 500.0
shear_axis = "x"
shear_velocity = 0.1
[output.frames]
every_steps = 50
[output.checkpoints]
every_steps = 100000
keep = 10
"""


def _final_state(run_dir):
    return read_checkpoint(list_checkpoints(run_dir / "checkpoints")[-1])


@pytest.fixture(scope="module")
def whole(tmp_path_factory):
    root = tmp_path_factory.mktemp("stages")
    (root / "case.toml").write_text(CASE)
    result = api.run(root / "case.toml", root / "whole")
    with h5py.File(root / "whole" / "trajectory.h5", "r") as f:
        stage = f["observables/stage/value"][...]
        times = f["observables/stage/time"][...]
    return root, result, stage, times


def test_every_stage_runs_and_ends_on_its_condition(whole):
    _, result, stage, times = whole
    assert set(stage.tolist()) == {0.0, 1.0, 2.0} and stage[-1] == 2.0  # the end sample: the last stage
    # when stages 1 and 2 started, and when the run ended: with the last stage
    starts = [times[np.argmax(stage == k)] for k in (1, 2)] + [times[-1]]
    assert starts[0] == pytest.approx(0.0003, abs=0.0001)  # kinetic energy test after min_time
    assert starts[1] - starts[0] == pytest.approx(0.0004, abs=1e-5)  # duration
    assert starts[2] - starts[1] == pytest.approx(3e-5 / 0.1, abs=2e-5)  # shear displacement
    assert result.time < 0.005  # the run ended with its last stage, before simulation.duration


@pytest.mark.parametrize("split", [0.0002, 0.0005, 0.00085], ids=["deposit", "load", "shear"])
def test_resume_inside_any_stage_is_bitwise(whole, split):
    root, result, _, _ = whole
    run_dir = root / f"split-{split}"
    api.run(root / "case.toml", run_dir, until=split)
    resumed = api.resume(run_dir)
    assert resumed.step == result.step
    a, b = _final_state(root / "whole"), _final_state(run_dir)
    assert a.arrays.keys() == b.arrays.keys()
    for module in a.arrays:
        for name in a.arrays[module]:
            assert np.array_equal(a.arrays[module][name], b.arrays[module][name]), f"{module}/{name}"
