"""configs/bedload.toml: bedload transport by the vans1d fluid over a bed of 1000 glass beads.

Above the threshold of motion (Shields number about 0.16 here) the sediment moves within
0.05 s (its steady rate, between Wong & Parker's and Meyer-Peter & Mueller's laws, is the
`sphere verify` case d4-vans1d-bedload-band). Not far below the threshold (slope 0.01 rad,
theta about 0.035, 0.7 of Wong & Parker's 0.0495) the bed stays put: Q* about 1e-3, the
rattling of surface grains. The bounds (above: Q* > 0.02; below: |Q*| < 0.005) sit between the
two measured regimes with a factor 2 or more of margin on each side.
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

import h5py
import numpy as np

from sphere_cli import api

CONFIGS = Path(__file__).parents[2] / "configs"
GRAVITY = "gravity = [0.490296, 0.0, -9.797740]"


def run_bedload(tmp_path: Path, slope: float | None, until: float = 0.05) -> dict:
    text = (CONFIGS / "bedload.toml").read_text()
    assert GRAVITY in text
    if slope is not None:
        text = text.replace(GRAVITY, f"gravity = [{9.81 * math.sin(slope)}, 0.0, {-9.81 * math.cos(slope)}]")
    text = text.replace("every_time = 0.05", "every_time = 0.01")
    (tmp_path / "bedload.toml").write_text(text)
    shutil.copy(CONFIGS / "bedload-bed.csv", tmp_path)
    api.run(tmp_path / "bedload.toml", tmp_path / "run", until=until)
    with h5py.File(tmp_path / "run" / "trajectory.h5", "r") as f:
        obs = f["observables"]
        assert obs["q_star"].attrs.get("unit", "1") in ("1", b"1")
        return {name: obs[name]["value"][...] for name in ("q_star", "shields_number", "bed_shear_stress")}


def test_bedload_config_transports_sediment(tmp_path):
    obs = run_bedload(tmp_path, slope=None)
    theta = obs["shields_number"]
    assert 0.12 < theta[-1] < 0.2
    # the bed shear stress is about rho_f g sin(alpha) times the water depth above the bed (6 d)
    depth = obs["bed_shear_stress"][0] / (1000.0 * 0.490296)
    assert 5 * 0.006 < depth < 7 * 0.006
    assert obs["q_star"][0] == 0.0  # the bed starts at rest
    assert np.mean(obs["q_star"][-2:]) > 0.02


def test_no_transport_not_far_below_the_threshold(tmp_path):
    obs = run_bedload(tmp_path, slope=0.01)
    assert 0.025 < obs["shields_number"][-1] < 0.045
    assert np.abs(obs["q_star"][1:]).max() < 0.005
