"""The Navier-Stokes fluid on a grid whose top follows a moving wall (`[fluid.grid]
follow_top_wall`), driven through physics/navier_stokes.NavierStokesSolver without particles:
the arbitrary Lagrangian-Eulerian terms of kernels/fluid/navier_stokes.py (geometric conservation law,
Thomas & Lombard 1979).

- zero forcing stays zero: a column at rest under gravity, closed at the bottom, open at the
  moving top (p = p_top), stays at rest while its grid stretches or shrinks, and its pressure is
  the hydrostatic p_top + rho g (H(t) - z) of the current cells, and the pore volume the grid
  gains or loses passes through the open top;
- mass conservation: a column of uniform porosity whose solid (volume fraction (1 - phi) H =
  const, incompressible grains) is compressed by the top moving down expels through the top
  exactly the volume the column loses, A |dH/dt|, and inside the column the flux phi u grows
  linearly from the closed bottom (continuity: phi u = -z dphi/dt);
- coupled to particles at rest far below a moving top: no flow, hydrostatic pressure.
"""

from __future__ import annotations

import numpy as np
import pytest
from test_darcy_coupled import bed_at_rest_case

from sphere_cli.config.fluid_navier_stokes import NavierStokesFluid
from sphere_cli.config.load import parse_case
from sphere_cli.physics.fluid.grid import FluidGrid
from sphere_cli.physics.fluid.navier_stokes import NavierStokesSolver
from sphere_cli.scene.builder import build_scene
from sphere_cli.simulation import advance

RHO = 1000.0  # kg/m^3
G = 9.81  # m/s^2
TOL = 1e-10  # pressure solver tolerance
SHAPE, SIDE, HEIGHT = (4, 4, 8), 0.04, 0.08  # cells, box side and initial height [m]
DRIFT = 0.01  # m/s, a uniform horizontal flow
DT, STEPS = 1e-3, 200  # s: the viscous limit dx^2/(8 nu) at mu = 1e-3 Pa s is 0.1 s


def _solver(**fluid) -> NavierStokesSolver:
    grid = FluidGrid(
        origin=np.zeros(3),
        spacing=np.array([SIDE, SIDE, HEIGHT]) / np.array(SHAPE),
        shape=SHAPE,
        periodic=np.array([True, True, False]),
    )
    config = NavierStokesFluid.model_validate(
        {
            "model": "navier-stokes",
            "density": RHO,
            "grid": {"follow_top_wall": True},
            "solver": {"tolerance": TOL},
            **fluid,
        }
    )
    return NavierStokesSolver(config, grid, (0.0, 0.0, -G))


@pytest.mark.parametrize(
    ("speed", "phi", "beta"),
    [(0.05, 1.0, 0.0), (-0.05, 1.0, 0.0), (0.05, 0.6, 0.0), (-0.05, 1.0, 1.0)],
)
def test_column_at_rest_stays_at_rest_on_a_moving_grid(speed, phi, beta):
    """Validation C ("zero forcing stays zero") on a moving grid: the top wall moves at `speed`
    [m/s] (12.5 % of the height over the run), the porosity is uniform and fixed. The grid's
    own flux and the cells' volume change cancel (geometric conservation law), so nothing
    flows, and a uniform drift along x (free-slip walls) is carried unchanged (the grid's
    momentum flux and the cells' volume change cancel as well): v - (DRIFT, 0, 0) stays at
    round-off (< 1e-9 m/s, as the fixed-grid column of
    test_fluid_navier_stokes.py) and p = p_top + rho g (H(t) - z) at the current cell centres to
    1e-9 rho g H (the solver tolerance 1e-10 times the conditioning of a 8-cell column)."""
    p_top = 100.0
    solver = _solver(old_pressure_weight=beta, top={"type": "pressure", "pressure": p_top})
    fs = solver.allocate()
    fs.porosity[...] = phi
    solver.set_velocity(fs, (DRIFT, 0.0, 0.0))
    solver.initial_pressure(fs, 0.0)
    worst = 0.0
    for step in range(STEPS):
        height = HEIGHT + speed * (step + 1) * DT
        solver.resize(height)
        solver.step(fs, step * DT, DT)
        drift = fs.v_face[:, :, :-1, 0] - DRIFT
        worst = max(worst, float(np.abs(fs.v_face[..., 1:]).max()), float(np.abs(drift).max()))
        exact = p_top + RHO * G * (height - solver.grid.centres(2))
        assert np.abs(fs.p - exact[None, None, :]).max() <= 1e-9 * RHO * G * HEIGHT, step
    assert worst < 1e-9
    assert fs.height == height
    # the pores the grid gains (or loses) are filled through (or emptied out of) the open top
    assert -fs.outflow == pytest.approx(phi * SIDE**2 * (height - HEIGHT), rel=1e-7)


def test_compressed_column_expels_the_volume_it_loses():
    """Mass conservation on a shrinking grid: solid fraction 0.6 of the initial column, top wall
    moving down at 0.02 m/s (5 % of the height over 200 steps), phi(t) = 1 - 0.6 H0/H(t) imposed
    on every cell with its backward difference dphi. The grains are incompressible, so the pore
    volume sum(phi V) = A H - solid falls by A |dH| a step, and the fluid that leaves through the
    moving top (relative to it, the solver's fs.outflow) must equal it. The discrete ALE
    continuity makes this an identity up to the pressure solve: relative 1e-7 is allowed (1e-10
    residual per solve over 200 solves, each solve's error at most the residual times the
    conditioning of an 8-cell column); leaving out either moving-grid term misses it by the
    order of the whole volume change.

    Inside, continuity with uniform phi gives the interstitial velocity u(z) = -z phi'/phi
    (zero at the closed bottom), checked at the inner faces to 1 % (the fluid's inertia over a
    step)."""
    speed, solid = -0.02, 0.6
    area = SIDE * SIDE
    solver = _solver()
    fs = solver.allocate()
    phi_old = 1.0 - solid
    fs.porosity[...] = phi_old
    solver.initial_pressure(fs, 0.0)
    pore0 = float(fs.porosity.sum()) * solver.grid.cell_volume
    height = HEIGHT
    for step in range(STEPS):
        height = HEIGHT + speed * (step + 1) * DT
        phi_new = 1.0 - solid * HEIGHT / height
        solver.resize(height)
        fs.porosity[...] = phi_new
        fs.porosity_rate[...] = (phi_new - phi_old) / DT
        solver.step(fs, step * DT, DT)
        phi_old = phi_new
    expelled = area * (HEIGHT - height)
    pore = float(fs.porosity.sum()) * solver.grid.cell_volume
    assert pore0 - pore == pytest.approx(expelled, rel=1e-12)
    assert fs.outflow == pytest.approx(expelled, rel=1e-7)
    rate = float(fs.porosity_rate[0, 0, 0])  # dphi/dt of the last step [1/s]
    faces = solver.grid.centres(2)[1:] - 0.5 * solver.grid.spacing[2]
    face_velocity = fs.v_face[..., 1:-1, 2]
    exact = -faces * rate / phi_old
    np.testing.assert_allclose(face_velocity, np.broadcast_to(exact, face_velocity.shape), rtol=0.01)
    assert np.abs(fs.v_face[..., :2]).max() < 1e-9


@pytest.mark.parametrize("speed", [0.2, -0.2])
def test_grains_at_rest_far_below_a_moving_top_see_no_flow(speed):
    """Coupled to particles (physics/fluid/navier_stokes.py): four layers of 1 mm grains at rest
    on a closed floor (the Darcy bed of tests/physics/test_darcy_coupled.py), a drained top
    wall 17-21 mm above them moving down or up at 0.2 m/s, the grid (2 x 2 x 4 cells) following
    it. The grains do not move, so the water should stay at rest and hydrostatic whatever the
    grid does. The porosity rate of cells moving with the grid (two lens estimates of a cell
    that slid past the grains) did not cancel the porosity the moving faces carry: the water
    flowed at 2.8 cm/s and the pressure at the bed's base was 2.6 Pa off hydrostatic. The rate
    is now taken in a frame moving with the grains (kernels/fluid/porosity.py
    rate_in_grains_frame), here fixed in space: measured 3e-7 and 1.1e-6 m/s and 1.4e-5 and
    4.9e-5 Pa off rho g (H - z) of the cells now (the grains' settling jiggle of 1e-7 m/s),
    allowed 1e-5 m/s and 1e-3 Pa (the bed's buoyant weight per area is 34 Pa). The wall
    keeps H within 21-25 mm: above 26 mm these cells become 2.7 times as tall as the sampling
    sphere is wide and the coupling is unstable on a fixed grid too (user guide)."""
    top = 0.025 if speed > 0 else 0.021
    scene = build_scene(parse_case(bed_at_rest_case("navier-stokes", top, 4, speed)))
    start = scene.state.particles.pos.copy()
    advance(scene, 5000)
    fs, grid = scene.fluid.fs, scene.fluid.grid()
    assert fs.height == pytest.approx(0.046 - top, abs=1e-9)  # the wall moved 4 mm
    assert np.abs(scene.state.particles.pos - start).max() < 1e-6
    assert np.abs(fs.v_face).max() < 1e-5
    hydrostatic = RHO * G * (fs.height - (grid.centres(2) - grid.origin[2]))
    assert np.abs(fs.p - hydrostatic[None, None, :]).max() < 1e-3


@pytest.mark.parametrize("model", ["navier-stokes", "darcy"])
def test_cells_stretched_past_their_sampling_parts_are_warned_of_once(model, caplog):
    """A grid following a rising wall keeps the sampling parts counted from the case's cells
    (physics/fluid/porosity.py sampling_parts: 6.225 mm over the 2.5 mm sphere, 2.49: two
    spheres a cell); once the cells are stretched to where three would be taken (2.5 at 6.25
    mm), the run warns once, naming the cells and both counts."""
    scene = build_scene(parse_case(bed_at_rest_case(model, 0.0249, 4, -0.2)))
    with caplog.at_level("WARNING", logger="sphere"):
        advance(scene, 100)  # 0.08 mm: cells of 6.245 mm, 2.498
        assert not [r for r in caplog.records if "sampled in" in r.getMessage()]
        advance(scene, 400)  # 0.4 mm in all: 6.325 mm, 2.53
    told = [r.getMessage() for r in caplog.records if "sampled in" in r.getMessage()]
    assert len(told) == 1, told
    assert "1 x 1 x 3 parts" in told[0] and "the 1 x 1 x 2 counted" in told[0], told[0]
