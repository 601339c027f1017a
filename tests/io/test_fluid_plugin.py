"""The fluid plug-in (physics/fluid_plugin.py): a dry scene carries nothing of a fluid, and every hook a
fluid model has is wired into the step, the stability guard, the time-step limit, the
trajectory, the XDMF sidecar, `inspect` and a bitwise resume.

The hooks are exercised with a toy model: a uniform upward body force on every particle whose
size is a counter advanced every third step (a stand-in for a fluid state that evolves on its
own schedule), written as a 3D grid field."""

from __future__ import annotations

import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path
from types import SimpleNamespace

import h5py
import numpy as np
import pytest

from sphere_cli import api
from sphere_cli.errors import NumericalError
from sphere_cli.io.checkpoint import list_checkpoints, read_checkpoint
from sphere_cli.physics.fluid_plugin import FluidModule
from sphere_cli.scene import builder as scene_module

CASE = """
[simulation]
duration = {duration}
dt = 1.0e-5
stability = "contact"
[domain]
upper = [0.01, 0.01, 0.02]
[particles]
count = 12
density = 2500.0
radius = {{ distribution = "fixed", value = 0.0008 }}
[contact]
model = "linear"
normal_stiffness = 1.0e4
[[walls]]
face = "z-"
[output]
frames = {{ every_steps = 10 }}
checkpoints = {{ every_steps = 20 }}
"""

SHAPE = (2, 3, 4)


class ToyFluid(FluidModule):
    model = "toy"

    def __init__(self, loaded, state, limit=np.inf, blow_up_at=None, push=1e-7):
        super().__init__(loaded, state)
        self.push = push
        self.counter = np.zeros(SHAPE)
        self.limit = limit
        self.blow_up_at = blow_up_at
        state.fluid = self

    def dt_limit(self):
        return self.limit, "the toy fluid's made-up limit"

    def forces(self, state, spring_dt=None):
        state.particles.force[:, 2] += self.push * self.counter[0, 0, 1]

    def start(self, state):
        self.coupling_steps = 3  # after_step every third step

    def after_step(self, state):
        assert state.clock.step % 3 == 0
        self.counter += np.arange(self.counter.size).reshape(SHAPE)
        if self.blow_up_at is not None and state.clock.step >= self.blow_up_at:
            self.counter[1, 2, 3] = np.nan

    def prognostic_state(self, state):
        return {"counter": self.counter}

    def restore(self, state, arrays):
        self.counter[...] = arrays["counter"]

    def first_unstable(self, state):
        bad = np.argwhere(~np.isfinite(self.counter))
        return f"counter is not finite in cell {tuple(int(i) for i in bad[0])}" if bad.size else None

    def output_fields(self, state):
        return {"counter": (self.counter, "1"), "vector": (np.stack([self.counter] * 3, axis=-1), "m s-1")}

    def grid(self):
        # duck-typed like physics/fluid/grid.py FluidGrid
        return SimpleNamespace(origin=np.zeros(3), spacing=np.array([0.005, 0.01 / 3, 0.005]), shape=SHAPE)

    def observables(self, state):
        return {"toy_total": (float(self.counter.sum()), "1")}


@pytest.fixture
def toy(monkeypatch):
    """Every scene built gets a ToyFluid (built with the options in `toy.options`)."""

    class Factory:
        options: dict = {}

    def build(loaded, state):
        return ToyFluid(loaded, state, **Factory.options)

    monkeypatch.setattr(scene_module, "build_fluid", build)
    return Factory


def _case(write_case, steps: int) -> Path:
    return write_case(CASE.format(duration=steps * 1.0e-5))


# anything under a fluid folder: the models and their shared plumbing (grid, porosity, solver, drag)
DRY_RUN = """
import sys
from sphere_cli import api
api.run({case!r}, {run!r})
fluid = ("sphere_cli.physics.fluid", "sphere_cli.kernels.fluid")
loaded = sorted(m for m in sys.modules if m in fluid or m.startswith(tuple(f + "." for f in fluid)))
print("LOADED", loaded)
"""


def test_dry_scene_has_nothing_of_a_fluid(tmp_path: Path, write_case):
    """Run a dry case in a fresh interpreter: no fluid model module is imported, and neither the
    trajectory nor the checkpoints hold a fluid group."""
    case = _case(write_case, 20)
    script = tmp_path / "dry.py"
    script.write_text(DRY_RUN.format(case=str(case), run=str(tmp_path / "run")))
    done = subprocess.run([sys.executable, str(script)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert "LOADED []" in done.stdout
    with h5py.File(tmp_path / "run" / "trajectory.h5", "r") as f:
        assert "fluid" not in f
        assert not any(name.startswith("toy") for name in f["observables"])
    for path in list_checkpoints(tmp_path / "run" / "checkpoints"):
        assert "fluid" not in read_checkpoint(path).arrays
    assert api.inspect(tmp_path / "run")["trajectory"]["fluid"] is None


def test_fluid_hooks_reach_every_output(tmp_path: Path, write_case, toy):
    run_dir = tmp_path / "run"
    api.run(_case(write_case, 30), run_dir)
    with h5py.File(run_dir / "trajectory.h5", "r") as f:
        group = f["fluid"]
        assert group.attrs["model"] == "toy"
        assert tuple(group.attrs["shape"]) == SHAPE
        counter = group["counter/value"]
        assert counter.shape == (4, *SHAPE[::-1])  # frames at steps 0, 10, 20, 30; stored z-major
        assert list(group["counter/step"][...]) == [0, 10, 20, 30]
        increments = 30 // 3
        expected = increments * np.arange(np.prod(SHAPE)).reshape(SHAPE)
        assert np.array_equal(counter[-1], expected.transpose(2, 1, 0))
        assert group["vector/value"].shape == (4, *SHAPE[::-1], 3)
        assert f["observables/toy_total/value"][-1] == expected.sum()
    final = read_checkpoint(list_checkpoints(run_dir / "checkpoints")[-1])
    assert np.array_equal(final.arrays["fluid"]["counter"], expected)

    xmf = ET.parse(run_dir / "trajectory.xmf").getroot()
    meshes = xmf.findall(".//Topology[@TopologyType='3DCoRectMesh']")
    assert len(meshes) == 4
    assert meshes[0].get("Dimensions") == f"{SHAPE[2] + 1} {SHAPE[1] + 1} {SHAPE[0] + 1}"
    with h5py.File(run_dir / "trajectory.h5", "r") as f:
        for item in xmf.iter("DataItem"):
            if item.get("Format") == "HDF":
                name, dataset = item.text.split(":")
                dims = tuple(int(d) for d in item.get("Dimensions").split())
                assert f[dataset].shape == dims, dataset

    summary = api.inspect(run_dir)["trajectory"]["fluid"]
    assert summary["model"] == "toy"
    assert summary["grid_cells"] == list(SHAPE)
    assert "counter" in summary


def test_fluid_force_reaches_the_particles(toy):
    """With the toy's upward push the particles end higher than without it."""
    text = CASE.format(duration=1.0)
    pushed = api.run_in_memory(text, 60).state.particles.pos[:, 2].copy()
    toy.options = {"push": 0.0}
    plain = api.run_in_memory(text, 60).state.particles.pos[:, 2]
    assert pushed.mean() > plain.mean() + 1e-9


def test_resume_with_a_fluid_is_bitwise(tmp_path: Path, write_case, toy):
    case = _case(write_case, 60)
    api.run(case, tmp_path / "whole")
    api.run(case, tmp_path / "split", until=25 * 1.0e-5)
    api.resume(tmp_path / "split")
    a = read_checkpoint(list_checkpoints(tmp_path / "whole" / "checkpoints")[-1]).arrays
    b = read_checkpoint(list_checkpoints(tmp_path / "split" / "checkpoints")[-1]).arrays
    assert a.keys() == b.keys() and "fluid" in a
    for module in a:
        for name in a[module]:
            assert np.array_equal(a[module][name], b[module][name]), f"{module}/{name}"


def test_fluid_limit_sets_auto_dt_and_refuses_a_larger_one(write_case, toy):
    from sphere_cli.config.load import parse_case
    from sphere_cli.errors import CaseError

    toy.options = {"limit": 1.0e-6}
    text = CASE.format(duration=1.0)
    scene = scene_module.build_scene(parse_case(text.replace("dt = 1.0e-5", 'dt = "auto"')))
    safety = scene.case.simulation.dt_safety  # the default: of the fluid's limit, which is lower
    assert scene.state.clock.dt == pytest.approx(safety * 1.0e-6)
    assert "toy fluid" in scene.dt_limit_reason
    with pytest.raises(CaseError, match="toy fluid's made-up limit"):
        scene_module.build_scene(parse_case(text))


def test_fluid_failure_is_caught_and_named(tmp_path: Path, write_case, toy):
    toy.options = {"blow_up_at": 15}
    with pytest.raises(NumericalError, match=r"in the fluid: counter is not finite in cell \(1, 2, 3\)"):
        api.run(_case(write_case, 60), tmp_path / "run")
    for path in list_checkpoints(tmp_path / "run" / "checkpoints"):
        counter = read_checkpoint(path).arrays["fluid"]["counter"]
        assert np.isfinite(counter).all()
