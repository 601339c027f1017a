"""A run with the Navier-Stokes fluid stopped and resumed ends bitwise in the state of an
uninterrupted one -- also when it stops in the middle of a fluid step's block of DEM steps --
and its fluid frames match. The fluid's checkpoint group holds the whole fluid state."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import pytest

from sphere_cli import api
from sphere_cli.config.load import load_case
from sphere_cli.io.checkpoint import FORMAT, list_checkpoints, read_checkpoint
from sphere_cli.scene.builder import build_scene

CASE = """
[simulation]
duration = 1.0
dt = 4.0e-6
stability = "contact"
threads = 1
[domain]
upper = [0.01, 0.01, 0.02]
periodic = [true, true, false]
[particles]
count = 24
density = 2500.0
radius = { distribution = "uniform", min = 0.0004, max = 0.0005 }
placement = { method = "lattice", region_lower = [0.0, 0.0, 0.004], region_upper = [0.01, 0.01, 0.016] }
velocity = [0.0, 0.0, -0.05]
[contact]
normal_stiffness = 1.0e4
[[walls]]
face = "z-"
[fluid]
model = "navier-stokes"
grid = { cells = [4, 4, 8] }
old_pressure_weight = 0.5
top = { type = "pressure", pressure = 100.0, amplitude = 50.0, period = 0.005 }
[fluid.coupling]
steps = 7
[output]
frames = { every_steps = 10 }
checkpoints = { every_steps = 1000 }
"""
STEPS = 200
SPLIT = (
    101  # not a multiple of the 7 DEM steps a fluid step: the resumed run starts inside a fluid step's block
)


def _final_state(run_dir: Path) -> dict:
    return read_checkpoint(list_checkpoints(run_dir / "checkpoints")[-1]).arrays


@pytest.mark.parametrize("averaging", ["particle", "cell"])
def test_fluid_resume_is_bitwise_identical(tmp_path, write_case, averaging):
    """Both drag averagings: the cell-averaged drag's means and shares are in the checkpoint."""
    case = write_case(
        CASE.replace("[fluid.coupling]", f'[fluid.drag]\naveraging = "{averaging}"\n[fluid.coupling]')
    )
    dt = build_scene(load_case(case)).state.clock.dt
    whole = api.run(case, tmp_path / "whole", until=STEPS * dt)
    api.run(case, tmp_path / "split", until=SPLIT * dt)
    split = api.resume(tmp_path / "split", until=STEPS * dt)
    assert whole.step == split.step == STEPS
    a, b = _final_state(tmp_path / "whole"), _final_state(tmp_path / "split")
    assert a.keys() == b.keys() and "fluid" in a
    for module in a:
        assert a[module].keys() == b[module].keys()
        for name in a[module]:
            assert np.array_equal(a[module][name], b[module][name]), f"{module}/{name} differs"
    assert int(a["fluid"]["steps"]) == STEPS // 7
    assert np.abs(a["fluid"]["v"]).max() > 0  # the sinking particles stirred the fluid
    with (
        h5py.File(tmp_path / "whole" / "trajectory.h5") as fw,
        h5py.File(tmp_path / "split" / "trajectory.h5") as fs,
    ):
        for name in ("pressure", "velocity", "porosity", "interaction_force"):
            steps_w = list(fw[f"fluid/{name}/step"][...])
            steps_s = list(fs[f"fluid/{name}/step"][...])
            for step in set(steps_w) & set(steps_s):
                assert np.array_equal(
                    fw[f"fluid/{name}/value"][steps_w.index(step)],
                    fs[f"fluid/{name}/value"][steps_s.index(step)],
                ), (name, step)


def test_a_checkpoint_of_the_collocated_grid_is_refused(tmp_path, write_case):
    """A checkpoint of format 3 holds the Navier-Stokes velocity at the cell centres; `sphere
    resume` refuses it (exit 78, EX_CONFIG) with a message naming the collocated grid and what to
    do, rather than skipping it for an older checkpoint or reading it as face velocities."""
    import subprocess
    import sys

    case = write_case(CASE)
    dt = build_scene(load_case(case)).state.clock.dt
    api.run(case, tmp_path / "run", until=30 * dt)
    for path in list_checkpoints(tmp_path / "run" / "checkpoints"):
        with h5py.File(path, "r+") as f:  # as format 3 wrote it: no face velocities
            f.attrs["format"] = 3
            del f["sphere/state/fluid/v_face"]
    result = subprocess.run(
        [sys.executable, "-m", "sphere_cli.cli", "resume", str(tmp_path / "run")],
        capture_output=True,
        text=True,
    )
    assert result.returncode == 78, result.stderr
    assert "collocated grid" in result.stderr and "Traceback" not in result.stderr
    assert "format 3" in result.stderr and f"format {FORMAT}" in result.stderr


def test_resume_finds_the_files_of_the_case_folder(tmp_path):
    """A case whose top pressure is a series in a file next to it (a relative path), run into a
    run directory elsewhere: `resume` reads the run's copy of the case but resolves the path
    from the folder of the case it was started from, and continues bitwise."""
    folder = tmp_path / "case"
    folder.mkdir()
    (folder / "top.csv").write_text("t,p\n0.0,0.0\n10.0,50.0\n")
    case = folder / "case.toml"
    case.write_text(
        "[simulation]\nduration = 5.0\ndt = 0.5\n[domain]\nupper = [0.01, 0.01, 0.02]\n"
        'periodic = [true, true, false]\n[fluid]\nmodel = "navier-stokes"\ngrid = { cells = [2, 2, 4] }\n'
        'top = { type = "pressure", series = "top.csv" }\n[output]\ncheckpoints = { every_steps = 2 }\n'
    )
    whole = api.run(case, tmp_path / "whole")
    api.run(case, tmp_path / "split", until=2.0)
    split = api.resume(tmp_path / "split")
    assert whole.step == split.step == 10
    a, b = _final_state(tmp_path / "whole"), _final_state(tmp_path / "split")
    for name in a["fluid"]:
        assert np.array_equal(a["fluid"][name], b["fluid"][name]), name


def test_resume_refuses_an_edited_series_file(tmp_path):
    """The run records the SHA-256 of the files it reads again on resume (here the top pressure
    series) with its case: a series edited after the run started is refused like an edited key
    (exit 78, naming the file's key), not read as if it had always been so."""
    from sphere_cli.errors import ResumeRefused

    (tmp_path / "top.csv").write_text("t,p\n0.0,0.0\n10.0,50.0\n")
    case = tmp_path / "case.toml"
    case.write_text(
        "[simulation]\nduration = 5.0\ndt = 0.5\n[domain]\nupper = [0.01, 0.01, 0.02]\n"
        'periodic = [true, true, false]\n[fluid]\nmodel = "navier-stokes"\ngrid = { cells = [2, 2, 4] }\n'
        'top = { type = "pressure", series = "top.csv" }\n[output]\ncheckpoints = { every_steps = 2 }\n'
    )
    api.run(case, tmp_path / "run", until=2.0)
    (tmp_path / "top.csv").write_text("t,p\n0.0,0.0\n10.0,80.0\n")
    with pytest.raises(ResumeRefused, match="input_files.fluid.top.series"):
        api.resume(tmp_path / "run")
