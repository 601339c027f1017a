"""The step is built once from the module protocol (physics/module.py): the builder's order
keeps every ordering constraint, each hook runs only for the modules that define it, and
docs/architecture.md's hook table is the protocol's."""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from sphere_cli.config.load import load_case, parse_case
from sphere_cli.physics import module as protocol
from sphere_cli.physics.contact import PairContactForces
from sphere_cli.physics.fluid.darcy import Darcy
from sphere_cli.physics.fluid.navier_stokes import NavierStokes
from sphere_cli.physics.fluid.vans1d import Vans1d
from sphere_cli.physics.motion import Motion
from sphere_cli.physics.neighbors import NeighborSearch
from sphere_cli.physics.observe.energy_budget import EnergyBudget
from sphere_cli.physics.observe.observables import Observer
from sphere_cli.physics.stages import Stages
from sphere_cli.physics.walls import PlaneWallForces, WallMotion
from sphere_cli.scene.builder import build_scene

ROOT = Path(__file__).parents[2]
CONFIGS = sorted((ROOT / "configs").glob("*.toml"))
MODULES = (
    Motion, NeighborSearch, PairContactForces, EnergyBudget, PlaneWallForces, WallMotion, Stages,
    Observer, NavierStokes, Darcy, Vans1d,
)  # fmt: skip


def scene_of(config: Path, budget: bool = False):
    if not budget:
        return build_scene(load_case(config))
    text = re.sub(r"quantities = \[", 'quantities = ["energy_budget", ', config.read_text())
    assert "energy_budget" in text
    return build_scene(parse_case(text, config))


@pytest.mark.parametrize("config", CONFIGS, ids=[c.stem for c in CONFIGS])
def test_every_example_keeps_the_order(config):
    scene = scene_of(config)
    assert protocol.order_problems(scene.modules) == []
    step = scene.step
    # each hook tuple is the defining modules' methods, in the modules' order
    for hook in ("kick_drift", "prepare", "forces", "finish_step"):
        expected = [getattr(m, hook) for m in scene.modules if protocol.defines(m, hook)]
        assert list(getattr(step, hook)) == expected, hook
    assert step.prepare == (scene.neighbors.prepare,)


def test_the_budget_runs_before_the_contacts():
    scene = scene_of(ROOT / "configs" / "direct-shear.toml", budget=True)
    forces = list(scene.step.forces)
    assert forces.index(scene.budget.forces) < forces.index(scene.contact.forces)
    assert scene.step.finish_step == (scene.budget.finish_step,)


def test_a_wrong_order_is_named():
    scene = scene_of(ROOT / "configs" / "direct-shear.toml", budget=True)
    modules = list(scene.modules)
    budget, contact = modules.index(scene.budget), modules.index(scene.contact)
    modules[budget], modules[contact] = modules[contact], modules[budget]
    problems = protocol.order_problems(tuple(modules))
    assert len(problems) == 1
    assert problems[0].startswith("energy_budget.forces must run before contact.forces")


def test_a_fluid_with_implicit_drag_takes_the_particles_kick():
    scene = scene_of(ROOT / "configs" / "fluid-settling.toml")
    assert scene.step.kick == (scene.fluid.kick,)
    module, advance = scene.step.after_step[0]
    assert module is scene.fluid and advance == scene.fluid.after_step and module.coupling_steps == 10


def test_a_dry_scene_without_walls_runs_three_hooks():
    bed = ROOT / "configs" / "periodic-bed.toml"
    scene = build_scene(parse_case(re.sub(r"\[\[walls\]\][^\[]*", "", bed.read_text()), bed))
    assert [m.name for m in scene.modules] == ["particles", "neighbors", "contact", ""]
    step = scene.step
    assert step.kick_drift == (scene.motion.kick_drift,) and step.kick == (scene.motion.kick,)
    assert step.forces == (scene.contact.forces,)
    assert step.finish_step == () and step.after_step == ()


def hook_table() -> dict[str, list[str]]:
    """hook -> the modules the table of docs/architecture.md lists for it, in its order."""
    text = (ROOT / "docs" / "architecture.md").read_text(encoding="utf-8")
    section = text.split("## The module protocol", 1)[1].split("\n## ", 1)[0]
    rows = re.findall(r"^\| `(\w+)` \|[^|]*\|([^|]*)\|", section, flags=re.M)
    return {hook: re.findall(r"`(\w+)`", modules) for hook, modules in rows}


def test_the_architecture_hook_table_is_the_protocol():
    table = hook_table()
    assert list(table) == list(protocol.HOOKS)
    for hook, listed in table.items():
        default = getattr(protocol.Module, hook)
        defining = [cls.__name__ for cls in MODULES if getattr(cls, hook) is not default]
        assert sorted(listed) == sorted(defining), hook


def test_a_restored_wall_spring_of_minus_zero_counts_as_set():
    """A wall contact can leave its spring at -0.0 (a sliding-free contact); the run that set it
    clears it to +0.0 when the contact ends. The mask of set springs derived from a restored
    (or, on MPI ranks, a received) hist marks it too, so a resumed run clears it alike."""
    scene = scene_of(ROOT / "configs" / "direct-shear.toml")
    hist = np.zeros((3, 2, 3))
    hist[1, 0] = (-0.0, -0.0, 0.0)
    hist[2, 1, 2] = 1e-9
    mask = scene.walls._spring_mask(hist, 3)
    assert list(mask) == [0, 1, 2]
