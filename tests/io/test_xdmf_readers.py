"""trajectory.xmf opened by the readers ParaView users have: ParaView's own XDMF 3 readers
(Xdmf3ReaderS and Xdmf3ReaderT, through pvbatch from Debian's python3-paraview, which `make test`
installs where apt-get is there) and the legacy XDMF reader that the VTK wheel carries. For the
demo and a Navier-Stokes run, each reader must give one time step per frame and, at the last
one, the particles (and the fluid cells) with every array equal to the HDF5 datasets.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import h5py
import numpy as np
import pytest
import vtk
from paraview_probe import describe

from sphere_cli import api

CONFIGS = Path(__file__).parents[2] / "configs"
PROBE = Path(__file__).with_name("paraview_probe.py")
PVBATCH = shutil.which("pvbatch")
PARTICLE_FIELDS = {"radius", "velocity", "angular_velocity", "force"}  # radius + output.fields


@pytest.fixture(scope="module")
def runs(tmp_path_factory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("xdmf")
    api.run(CONFIGS / "demo.toml", root / "demo", until=0.02)  # 4 frames, no fluid
    api.run(CONFIGS / "fluid-settling.toml", root / "fluid", until=0.002)  # 2 frames, 5 x 5 x 10 cells
    return {"demo": root / "demo", "fluid": root / "fluid"}


def _check(seen: dict, run: Path) -> None:
    """The reader's view (paraview_probe.describe) against trajectory.h5."""
    with h5py.File(run / "trajectory.h5", "r") as f:
        traj = f["particles/trajectory"]
        assert seen["times"] == pytest.approx(traj["position/time"][...].tolist(), rel=1e-12, abs=0)
        blocks = seen["blocks"]
        particles = next(b for b in blocks if b["points"] == traj["radius"].shape[0] and b["cells"])
        assert np.array_equal(particles["coordinates"], traj["position/value"][-1])
        assert set(particles["point_arrays"]) == PARTICLE_FIELDS
        assert np.array_equal(np.ravel(particles["point_arrays"]["radius"]), traj["radius"][...])
        for name in PARTICLE_FIELDS - {"radius"}:
            assert np.array_equal(particles["point_arrays"][name], traj[f"{name}/value"][-1]), name
        if "fluid" not in f or "shape" not in f["fluid"].attrs:
            assert len(blocks) == 1
            return
        nx, ny, nz = (int(n) for n in f["fluid"].attrs["shape"])
        fluid = next(b for b in blocks if b is not particles)
        assert fluid["points"] == (nx + 1) * (ny + 1) * (nz + 1) and fluid["cells"] == nx * ny * nz
        grid_fields = [n for n, g in f["fluid"].items() if g["value"].shape[1:4] == (nz, ny, nx)]
        assert set(fluid["cell_arrays"]) == set(grid_fields) and {"pressure", "velocity"} <= set(grid_fields)
        for name in grid_fields:
            stored = f[f"fluid/{name}/value"][-1]  # (nz, ny, nx[, 3]): x fastest, as VTK's cells
            expected = stored.reshape(nx * ny * nz, -1)
            assert np.array_equal(np.asarray(fluid["cell_arrays"][name]), expected), name


@pytest.mark.parametrize("name", ["demo", "fluid"])
def test_vtk_legacy_xdmf_reader(runs, name):
    reader = vtk.vtkXdmfReader()
    reader.SetFileName(str(runs[name] / "trajectory.xmf"))
    reader.UpdateInformation()
    times = reader.GetOutputInformation(0).Get(vtk.vtkStreamingDemandDrivenPipeline.TIME_STEPS())
    reader.UpdateTimeStep(times[-1])
    seen = describe(list(times), reader.GetOutputDataObject(0))
    _check(seen, runs[name])
    if name == "fluid":  # the same block names at every frame
        assert [b["name"] for b in seen["blocks"]] == ["particles", "fluid"]


@pytest.mark.skipif(
    PVBATCH is None,
    reason="ParaView's pvbatch is not installed (make test installs Debian's python3-paraview where "
    "apt-get is available)",
)
@pytest.mark.parametrize("reader", ["Xdmf3ReaderS", "Xdmf3ReaderT"])
@pytest.mark.parametrize("name", ["demo", "fluid"])
def test_paraview_xdmf3_readers(runs, name, reader):
    result = subprocess.run(
        [PVBATCH, str(PROBE), reader, str(runs[name] / "trajectory.xmf")],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert result.returncode == 0, result.stderr
    assert "Skipping unrecognized array type" not in result.stdout + result.stderr
    seen = json.loads(result.stdout.strip().splitlines()[-1])
    _check(seen, runs[name])
