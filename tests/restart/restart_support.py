"""Helpers shared by the restart tests: a small case, and comparisons of final states and frames."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np

from sphere_cli.config.load import load_case
from sphere_cli.io.checkpoint import list_checkpoints, read_checkpoint
from sphere_cli.scene.builder import build_scene

# 40 spheres falling onto a floor; frames every 50 steps, checkpoints every 100 (format with
# duration = a number of seconds)
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


def step_dt(case_path: Path) -> float:
    return build_scene(load_case(case_path)).state.clock.dt


def final_state(run_dir: Path) -> dict:
    return read_checkpoint(list_checkpoints(run_dir / "checkpoints")[-1]).arrays


def assert_same_state(a: dict, b: dict) -> None:
    assert a.keys() == b.keys()
    for module in a:
        assert a[module].keys() == b[module].keys()
        for name in a[module]:
            assert np.array_equal(a[module][name], b[module][name]), f"{module}/{name} differs"


def frames(run_dir: Path) -> dict[int, np.ndarray]:
    with h5py.File(run_dir / "trajectory.h5", "r") as f:
        g = f["particles/trajectory/position"]
        return {int(s): v for s, v in zip(g["step"][...], g["value"][...], strict=True)}
