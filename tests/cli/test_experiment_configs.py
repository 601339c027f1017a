"""The experiment cases of configs/ (consolidation, uniaxial strain, triaxial, direct shear) run
every stage to its end when shortened: each duration and min_time divided by SHORTEN, so a
deposit ends on its duration and each later stage still starts, moves its walls and ends.
(configs/ as written, at full length, run as-is; tests/restart/test_bitwise_restart.py runs each
for a few hundred steps and tests/physics/test_direct_shear.py runs the direct shear in full.)
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import h5py
import numba
import numpy as np
import pytest

from sphere_cli import api
from sphere_cli.config.load import load_case

CONFIGS = Path(__file__).parents[2] / "configs"
EXPERIMENTS = ["consolidation", "uniaxial-strain", "triaxial", "direct-shear"]
SHORTEN = 20.0


def shortened(text: str, factor: float = SHORTEN) -> str:
    """The case text with every duration and min_time divided by `factor`."""

    def scale(match: re.Match) -> str:
        return f"{match.group(1)}{float(match.group(2)) / factor!r}"

    return re.sub(r"\b((?:duration|min_time) = )([0-9.eE+-]+)", scale, text)


@pytest.fixture(autouse=True)
def one_thread():
    previous = numba.get_num_threads()
    numba.set_num_threads(1)  # small scenes: a parallel region costs more than it saves
    yield
    numba.set_num_threads(previous)


@pytest.mark.parametrize("name", EXPERIMENTS)
def test_experiment_runs_every_stage(tmp_path, name):
    source = CONFIGS / f"{name}.toml"
    stages = len(load_case(source).case.stages)
    case = tmp_path / "case.toml"
    case.write_text(shortened(source.read_text()))
    api.run(case, tmp_path / "run")
    status = json.loads((tmp_path / "run" / "status.json").read_text())
    # stages end on their own conditions: the end reported is where the run truly ended
    assert status["state"] == "done" and status["end_step"] == status["step"] and status["eta_seconds"] == 0
    with h5py.File(tmp_path / "run" / "trajectory.h5", "r") as f:
        obs = f["observables"]
        # every stage sampled, the end sample in the last one (not one past it)
        stage = obs["stage/value"][...]
        assert set(stage.tolist()) == set(map(float, range(stages))) and stage[-1] == stages - 1
        faces = [face.decode() for face in obs.attrs["wall_faces"]]
        for series in (
            "wall_position",
            "wall_velocity",
            "wall_force",
            "wall_normal_stress",
            "wall_shear_stress",
        ):
            values = obs[series]["value"][...]
            assert values.shape[1] == len(faces) and np.all(np.isfinite(values))
        moved = obs["wall_position/value"][-1] - obs["wall_position/value"][0]
        assert moved[faces.index("z+")] < 0.0  # the top wall came down onto the bed
