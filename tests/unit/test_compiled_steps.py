"""Many dry DEM steps in one compiled call (physics/compiled_steps.py, kernels/steps.py): bitwise
the step-by-step loop, on the scenes it applies to, and left out where it does not apply."""

from __future__ import annotations

from pathlib import Path

import numba
import numpy as np
import pytest

from sphere_cli.bench.dem import canonical_case
from sphere_cli.config.load import load_case, parse_case
from sphere_cli.scene.builder import build_scene
from sphere_cli.simulation import advance

CONFIGS = Path(__file__).parents[2] / "configs"
STEPS = 1500


def _state(scene) -> dict:
    p, nl, w = scene.state.particles, scene.state.neighbors, scene.state.walls
    arrays = {name: getattr(p, name) for name in ("pos", "vel", "angvel", "force", "torque")}
    arrays["springs"] = nl.hist[: nl.start[-1]]
    arrays["nbr"] = nl.nbr
    if w is not None:
        arrays["wall springs"] = w.hist
    if scene.state.fluid is not None:
        arrays["fluid velocity"] = scene.state.fluid.column.u
    return arrays


def _case(name: str):
    """hertz-mixture: a pour onto six walls (Hertz-Mindlin, rolling resistance, two materials);
    bedload: 1000 beads under a 1D VANS flow (its force on the particles in the loop, its
    coupling every 1e-3 s between calls, periodic in x and y);
    canonical: 400 spheres packed close between six walls (linear law, friction), falling into
    contact; periodic: the same spheres periodic in x and y over a floor, thrown sideways at
    0.5 m/s, so that they cross the periodic faces and make the list stale often."""
    if name in ("hertz-mixture", "bedload"):
        return load_case(CONFIGS / f"{name}.toml")
    text = canonical_case(400, spacing=1.05)
    if name == "periodic":
        for face in ("x-", "x+", "y-", "y+"):
            text = text.replace(f'[[walls]]\nface = "{face}"\n', "")
        text = text.replace("[domain]\n", "[domain]\nperiodic = [true, true, false]\n")
        text = text.replace("[particles]\n", "[particles]\nvelocity = [0.5, 0.3, 0.0]\n")
        assert text.count("[[walls]]") == 2 and "periodic" in text and "0.5, 0.3" in text
    return parse_case(text)


@pytest.mark.parametrize("name", ["hertz-mixture", "canonical", "periodic", "bedload"])
@pytest.mark.parametrize("threads", [1, 2])
def test_compiled_steps_are_the_step_by_step_loop_bitwise(name, threads):
    numba.set_num_threads(threads)
    try:
        compiled, stepwise = build_scene(_case(name)), build_scene(_case(name))
        assert compiled.step.compiled is not None
        stepwise.step.compiled = None
        for scene in (compiled, stepwise):
            advance(scene, STEPS - 7)  # the end falls between list builds, not on one
            advance(scene, 7)
        # the runs rebuilt the list several times: the compiled loop stopped at stale lists
        assert compiled.state.neighbors.builds == stepwise.state.neighbors.builds >= 2
        assert compiled.state.clock.step == stepwise.state.clock.step == STEPS
        a, b = _state(compiled), _state(stepwise)
        assert np.count_nonzero(a["springs"].any(axis=1)) > 0  # contacts with friction
        for key in a:
            assert np.array_equal(a[key], b[key]), key
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)


@pytest.mark.parametrize("config", ["direct-shear", "fluidized-bed"])
def test_moving_walls_and_3d_fluids_keep_the_step_by_step_loop(config):
    """Moving walls (direct shear) have hooks of their own in the step; the Navier-Stokes force
    on the particles is more than one kernel call, and its implicit drag takes over the kick."""
    assert build_scene(load_case(CONFIGS / f"{config}.toml")).step.compiled is None


def test_a_wrapped_hook_keeps_the_step_by_step_loop():
    """A hook replaced by a wrapper (a benchmark's stopwatch) is called: no compiled steps."""
    scene = build_scene(load_case(CONFIGS / "demo.toml"))
    contact = scene.contact
    original = contact.forces
    contact.forces = lambda state, spring_dt=None: original(state, spring_dt)
    scene.order_modules()
    assert scene.step.compiled is None
