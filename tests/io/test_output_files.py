"""The run directory holds what the design guide promises: an H5MD trajectory with units, an
XDMF sidecar whose every reference resolves, checksummed checkpoints (newest K kept), status.json
and a log; a dry scene writes nothing of a fluid."""

from __future__ import annotations

import json
import textwrap
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import numpy as np
import pytest

from sphere_cli import api
from sphere_cli.io.checkpoint import list_checkpoints
from sphere_cli.io.rundir import RunOutput
from sphere_cli.io.trajectory import _append, _time_series

CASE = """
    title = "output layout"
    [simulation]
    duration = 0.004
    [domain]
    upper = [0.01, 0.01, 0.02]
    [particles]
    count = 30
    density = 2500.0
    [contact]
    model = "linear"
    normal_stiffness = 1.0e4
    [[walls]]
    face = "z-"
    [output]
    fields = ["velocity", "angular_velocity", "force", "torque"]
    [output.frames]
    every_steps = 100
    [output.checkpoints]
    every_steps = 100
    keep = 2
"""


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    tmp = tmp_path_factory.mktemp("layout")
    case = tmp / "case.toml"
    case.write_text(textwrap.dedent(CASE))
    api.run(case, tmp / "run")
    return tmp / "run"


def test_h5md_layout(run_dir: Path):
    with h5py.File(run_dir / "trajectory.h5", "r") as f:
        assert list(f["h5md"].attrs["version"]) == [1, 1]
        assert f["h5md/creator"].attrs["name"] == "sphere"
        traj = f["particles/trajectory"]
        assert traj["box"].attrs["dimension"] == 3
        assert traj["radius"].shape == (30,) and traj["radius"].attrs["unit"] == "m"
        frames = traj["position/step"].shape[0]
        assert frames >= 3
        for field, unit in (
            ("position", "m"),
            ("velocity", "m s-1"),
            ("angular_velocity", "s-1"),
            ("force", "N"),
            ("torque", "N m"),
        ):
            assert traj[f"{field}/value"].shape == (frames, 30, 3)
            assert traj[f"{field}/value"].attrs["unit"] == unit
            assert traj[f"{field}/time"].attrs["unit"] == "s"
        steps = traj["position/step"][...]
        assert steps[0] == 0 and all(s % 100 == 0 for s in steps[:-1])
        assert f["observables/kinetic_energy/value"].attrs["unit"] == "J"
        assert f["observables/contacts/value"].shape == (frames,)
        resolved = json.loads(f["parameters"].attrs["resolved_case"])
        assert resolved["title"] == "output layout"
        assert "threads" in f["sphere/provenance"].attrs
        names = []
        f.visit(names.append)
        assert not [n for n in names if "fluid" in n.lower()]


def test_xdmf_references_resolve(run_dir: Path):
    root = ET.parse(run_dir / "trajectory.xmf").getroot()
    grids = root.findall(".//Grid[@GridType='Uniform']")
    with h5py.File(run_dir / "trajectory.h5", "r") as f:
        assert len(grids) == f["particles/trajectory/position/step"].shape[0]
        for item in root.iter("DataItem"):
            if item.get("Format") == "HDF":
                filename, dataset = item.text.strip().split(":")
                assert filename == "trajectory.h5"
                dims = tuple(int(x) for x in item.get("Dimensions").split())
                assert f[dataset].shape == dims
    names = {a.get("Name") for a in grids[0].findall("Attribute")}
    assert {"radius", "velocity", "angular_velocity", "force", "torque"} <= names


def test_checkpoints_kept_and_checksummed(run_dir: Path):
    ckpts = list_checkpoints(run_dir / "checkpoints")
    assert len(ckpts) == 2
    with h5py.File(ckpts[-1], "r") as f:
        assert f.attrs["complete"] == 1
        assert f["sphere/state/particles/pos"].fletcher32
        assert set(f["sphere/state"]) == {"particles", "neighbors", "walls"}


def test_status_and_log(run_dir: Path):
    status = json.loads((run_dir / "status.json").read_text())
    assert status["state"] == "done"
    assert status["step"] == status["end_step"]
    log = (run_dir / "run.log").read_text()
    assert "done at step" in log and "checkpoint" in log
    assert (run_dir / "case.toml").read_text() == textwrap.dedent(CASE)


def test_status_says_running_from_the_first_steps_not_a_status_interval_later(tmp_path, monkeypatch):
    """status.json said "starting" (building the scene) until output.status_every_seconds had
    passed since the loop began: a batch monitor saw a short run, or one killed early, as never
    started. Read at every frame after the first: "running", at that frame's step."""
    seen = []
    frame = RunOutput.frame

    def frame_and_look(self, scene, last: bool = False):
        frame(self, scene, last)
        if scene.state.clock.step > 0 and not last:
            status = json.loads((tmp_path / "run" / "status.json").read_text())
            seen.append((status["state"], status.get("step"), scene.state.clock.step))

    monkeypatch.setattr(RunOutput, "frame", frame_and_look)
    case = tmp_path / "case.toml"
    case.write_text(textwrap.dedent(CASE).replace("[output]", "[output]\nstatus_every_seconds = 3600"))
    api.run(case, tmp_path / "run")
    assert seen and all(state == "running" for state, _, _ in seen), seen
    assert all(0 < at <= step for _, at, step in seen), seen


def test_every_warning_of_a_run_reaches_run_log(tmp_path, capsys):
    """While a run's log is open, the library's logged warnings (e.g. the porosity clamp,
    `sphere.fluid.*`) and Python warnings both reach run.log and stderr, and its notes (INFO, the
    Darcy porosity taken at porosity_max) run.log alone; closing the log detaches every route and
    gives the library's logger its level back."""
    import logging
    import warnings

    from sphere_cli.io.rundir import RunDirectory

    rundir = RunDirectory(tmp_path / "run")
    rundir.path.mkdir()
    level = logging.getLogger("sphere").level
    rundir.logger()
    logging.getLogger("sphere.fluid.porosity").warning("porosity below 0 clamped to 0 in %d cells", 3)
    logging.getLogger("sphere.fluid.darcy").info("porosity above porosity_max in %d cells", 5)
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        warnings.warn("the drag uses the floor there", RuntimeWarning, stacklevel=1)
    rundir.close_logger()
    logging.getLogger("sphere.fluid.porosity").warning("after the run")
    log = rundir.log_path.read_text()
    assert "WARNING porosity below 0 clamped to 0 in 3 cells" in log
    assert "WARNING RuntimeWarning: the drag uses the floor there" in log
    assert "INFO porosity above porosity_max in 5 cells" in log
    assert "after the run" not in log
    err = capsys.readouterr().err
    assert "porosity below 0 clamped to 0 in 3 cells" in err and "porosity_max" not in err
    assert logging.getLogger("sphere").level == level


def test_a_case_warning_prints_once_and_stays_out_of_the_root_logger(capsys):
    """A notebook that configures logging must not see a case's warning twice: warn() prints it
    and its logger does not pass it up to the root handlers (run.log gets it through a handler
    of its own during a run, tests/cli/test_darcy_bad_input.py)."""
    import logging

    from sphere_cli.config.load import warn

    warn("fluid.top.period = 1.0: example")
    assert capsys.readouterr().err.count("fluid.top.period = 1.0: example") == 1
    assert logging.getLogger("sphere.case").propagate is False


def test_a_series_row_of_the_wrong_shape_is_refused_before_anything_is_written(tmp_path):
    """The rows are written through h5py's low-level calls (io/trajectory.py): a row that does
    not have the series' row shape (a grid field left in memory order, say) is a programming
    error, refused before the series grows, as h5py's own write refused it."""
    with h5py.File(tmp_path / "t.h5", "w") as f:
        _time_series(f, "field", (2, 3, 4), np.float64, "m")
        _append(f["field"], 7, 0.5, np.arange(24.0).reshape(2, 3, 4))
        with pytest.raises(ValueError, match=r"\(4, 3, 2\)"):
            _append(f["field"], 8, 0.6, np.zeros((4, 3, 2)))
        assert f["field/value"].shape == (1, 2, 3, 4)
        assert f["field/value"][0].tolist() == np.arange(24.0).reshape(2, 3, 4).tolist()
        assert f["field/step"][...].tolist() == [7] and f["field/time"][...].tolist() == [0.5]
