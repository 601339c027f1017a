"""Frictionless contacts carry no tangential history (design guide, promise 3): with every
friction coefficient 0 the neighbour list and the walls hold no springs, the checkpoints write
none, and a resumed run is still bitwise the uninterrupted one. A stage that turns friction on
brings the springs back for the whole run."""

from __future__ import annotations

import re
from pathlib import Path

import numba
import numpy as np
from restart_support import assert_same_state, final_state, frames

from sphere_cli import api
from sphere_cli.config.load import load_case
from sphere_cli.scene.builder import build_scene
from sphere_cli.simulation import advance

CONFIGS = Path(__file__).parents[2] / "configs"
STEPS = 300


def without_friction(name: str, folder: Path) -> Path:
    text = re.sub(r"(?m)^friction = [0-9.eE+-]+", "friction = 0.0", (CONFIGS / f"{name}.toml").read_text())
    path = folder / f"{name}.toml"
    path.write_text(text)
    return path


def test_no_springs_are_allocated_or_written(tmp_path):
    case = without_friction("demo", tmp_path)
    scene = build_scene(load_case(case))
    previous = numba.get_num_threads()
    numba.set_num_threads(min(2, numba.config.NUMBA_NUM_THREADS))  # pairs across chunks: slots
    try:
        advance(scene, STEPS)
    finally:
        numba.set_num_threads(previous)
    nl = scene.state.neighbors
    assert nl.hist.shape[0] == 0 and scene.state.walls.hist.shape[0] == 0
    assert nl.start[-1] > 0  # pairs are listed, just without springs
    if numba.config.NUMBA_NUM_THREADS > 1:  # the slots of pairs across chunks cover every pair
        assert scene.contact.slots.shape[0] >= nl.start[-1]
    dt = scene.state.clock.dt
    api.run(case, tmp_path / "run", until=STEPS * dt)
    state = final_state(tmp_path / "run")
    assert "hist" not in state["neighbors"] and "hist" not in state["walls"]


def test_a_frictionless_resume_is_bitwise(tmp_path):
    case = without_friction("hertz-mixture", tmp_path)
    dt = build_scene(load_case(case)).state.clock.dt
    end = STEPS * dt
    api.run(case, tmp_path / "whole", until=end)
    api.run(case, tmp_path / "split", until=0.5 * end)
    api.resume(tmp_path / "split", until=end)
    assert_same_state(final_state(tmp_path / "whole"), final_state(tmp_path / "split"))
    a, b = frames(tmp_path / "whole"), frames(tmp_path / "split")
    assert a.keys() <= b.keys() and all(np.array_equal(a[s], b[s]) for s in a)


def test_a_stage_with_friction_keeps_the_springs(tmp_path):
    text = (CONFIGS / "consolidation.toml").read_text()
    text = re.sub(r"(?m)^friction = [0-9.eE+-]+", "friction = 0.0", text)
    text = text.replace("[[stages]]", "[[stages]]\nfriction = 0.3", 1)
    path = tmp_path / "case.toml"
    path.write_text(text)
    scene = build_scene(load_case(path))
    assert scene.tables.frictional
    assert scene.state.walls.hist.shape[0] == scene.state.particles.count
