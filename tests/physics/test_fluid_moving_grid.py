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
  linearly from the closed bottom (continuity: phi u = -z dphi/dt).
"""

from __future__ import annotations

import numpy as np
import pytest

from sphere_cli.config.fluid_navier_stokes import NavierStokesFluid
from sphere_cli.physics.fluid.grid import FluidGrid
from sphere_cli.physics.fluid.navier_stokes import NavierStokesSolver

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
