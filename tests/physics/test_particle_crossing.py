"""A particle may not skip fluid cells (physics/fluid/navier_stokes.py): dt = "auto" keeps the
fastest settling particle within half a cell a fluid step, a dt above that is refused, and a run
whose particle moves a whole cell a fluid step stops naming it. The settling speed it takes is
the drag law's own terminal velocity (physics/fluid/drag.py settling_speed)."""

from __future__ import annotations

import math

import pytest

from sphere_cli.config.drag import DragConfig
from sphere_cli.errors import CaseError
from sphere_cli.physics.fluid.drag import FluidParticleDrag
from sphere_cli.physics.fluid.grid import FluidGrid
from sphere_cli.verify.scenes import linear_contact, particle_scene, toml_table

G = 9.81


def drag(rho: float, mu: float, law: str = "gidaspow") -> FluidParticleDrag:
    grid = FluidGrid(origin=[0.0] * 3, spacing=[0.01] * 3, shape=(2, 2, 2), periodic=[True, True, False])
    return FluidParticleDrag(DragConfig(law=law), rho, mu, grid, 1, False)


def test_settling_speed_in_the_stokes_and_newton_regimes():
    """10 um glass in glycerol (Re 3e-7): Stokes' (rho_p - rho_f) g d^2/(18 mu) to 1e-6; 5 mm
    steel in water (Re 5000, the Wen-Yu line's C_d = 0.44 above Re 1000): Newton's
    sqrt(4 g d (rho_p - rho_f)/(3 C_d rho_f)) to 1e-9; a sphere lighter than the fluid rises
    as fast as one as much heavier sinks; no gravity, no speed."""
    d = 10e-6
    stokes = (2500.0 - 1260.0) * G * d * d / (18 * 1.41)
    assert drag(1260.0, 1.41).settling_speed(d, 2500.0 - 1260.0, G) == pytest.approx(stokes, rel=1e-6)
    d = 5e-3
    newton = math.sqrt(4 * G * d * 6800.0 / (3 * 0.44 * 1000.0))
    water = drag(1000.0, 1e-3)
    assert water.settling_speed(d, 6800.0, G) == pytest.approx(newton, rel=1e-9)
    assert water.settling_speed(d, -500.0, G) == water.settling_speed(d, 500.0, G)
    assert water.settling_speed(d, 6800.0, 0.0) == 0.0
    # Di Felice's slow-flow drag is 0.96 of Stokes': the speed 1/0.96 of Stokes', within the bracket
    d = 10e-6
    di_felice = drag(1260.0, 1.41, "di-felice").settling_speed(d, 1240.0, G)
    assert di_felice == pytest.approx(stokes / 0.96, rel=2e-3)


def steel_in_water(dt, cells=4, vel=None, **keys):
    """A 5 mm steel sphere in water in a column 16 d wide on `cells` cells across (20 mm), more
    [fluid] keys in `keys`."""
    fluid = {
        "model": "navier-stokes",
        "grid": {"cells": [cells, cells, 32]},
        "top": {"type": "no-flow"},
        **keys,
    }
    return particle_scene(
        [[0.04, 0.04, 0.6]], 0.0025, vel, contact=linear_contact(1e3, 0.5, 0.5), density=7800.0,
        gravity=(0.0, 0.0, -G), upper=(0.08, 0.08, 0.64), periodic=(True, True, False), dt=dt,
        extra_tables=toml_table("fluid", fluid),
    )  # fmt: skip


def test_auto_dt_keeps_the_settling_particle_within_half_a_cell_and_a_larger_dt_is_refused():
    """The lone sphere has no contact to limit dt, and the viscous limit of 20 mm water cells is
    50 s: dt = "auto" is set by half a cell (10 mm) over the Newton settling speed, 1.005 m/s
    (times the safety factor); dt = 0.02 s, two cells a fluid step, is refused naming the key and
    the limit."""
    scene = steel_in_water("auto")
    newton = math.sqrt(4 * G * 5e-3 * 6800.0 / (3 * 0.44 * 1000.0))
    assert scene.dt_limit == pytest.approx(0.5 * 0.02 / newton, rel=1e-9)
    assert "cross 0.5 of a cell" in scene.dt_limit_reason
    assert scene.state.clock.dt <= scene.dt_limit
    with pytest.raises(CaseError, match=r"simulation\.dt.*above the stability limit 0\.009947 s.*cross 0\.5"):
        steel_in_water(0.02)


def test_the_limit_does_not_depend_on_the_velocities_and_the_run_check_stops_a_fast_particle():
    """A resume rebuilds the scene with the checkpoint's velocities and must find the same dt:
    the limit takes the settling speed only (radii and masses, restored unchanged), the same for
    the sphere at rest and thrown at 5 m/s. At dt = 0.8 ms (one DEM step a fluid step) 5 m/s
    crosses 0.2 of a 20 mm cell a fluid step, which passes the run's check; 50 m/s, 1.99
    cells, is stopped naming it; a NaN speed is left to the motion check, not reported as a
    crossing."""
    at_rest = steel_in_water("auto")
    thrown = steel_in_water("auto", vel=[[5.0, 0.0, 0.0]])
    assert thrown.dt_limit == at_rest.dt_limit and thrown.state.clock.dt == at_rest.state.clock.dt
    p = thrown.state.particles
    assert thrown.fluid.first_unstable(thrown.state) is None  # 5 m/s x 0.8 ms = 0.2 cells
    p.vel[0] = [50.0, 0.0, 0.0]
    assert "moves 1.99 cells (0.02 m) a fluid step at 50 m/s" in thrown.fluid.first_unstable(thrown.state)
    p.vel[0] = [math.nan, 0.0, 0.0]
    assert thrown.fluid.first_unstable(thrown.state) is None


def test_a_declared_fluid_speed_adds_to_the_settling_speed():
    """fluid.max_speed = 0.1 m/s (particles may be carried that fast by the flow): half a cell
    over 1.005 + 0.1 m/s, 9.0 ms, the reason naming both (the advective limit of 0.1 m/s on 20 mm
    cells, 33 ms, does not bind)."""
    scene = steel_in_water("auto", max_speed=0.1)
    newton = math.sqrt(4 * G * 5e-3 * 6800.0 / (3 * 0.44 * 1000.0))
    assert scene.dt_limit == pytest.approx(0.5 * 0.02 / (newton + 0.1), rel=1e-9)
    assert "plus fluid.max_speed = 0.1 m/s" in scene.dt_limit_reason
