"""C: the porous Navier-Stokes fluid alone (shared/validation/README.md, section C), driven
through physics/navier_stokes.NavierStokesSolver on imposed porosity, without particles.

- no forcing at all: p and v stay exactly 0;
- hydrostatic column: a fluid at rest under gravity stays at rest (|v| < 1e-9 m/s over 1000
  steps) with a pressure linear in depth to the solver tolerance;
- decaying shear wave u_x = A sin(k y) exp(-nu k^2 t) in a periodic box: rate nu k^2 within 1 %
  at 32 cells per wavelength, observed spatial order 2, the same for uniform porosity phi < 1;
- the pressure solve by PCG and by the reference's Jacobi iteration give the same step.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sphere_cli.config.fluid_navier_stokes import NavierStokesFluid
from sphere_cli.physics.fluid_grid import FluidGrid
from sphere_cli.physics.navier_stokes import NavierStokesSolver

RHO = 1000.0  # kg/m^3
G = 9.81  # m/s^2


def _grid(shape, length) -> FluidGrid:
    shape = tuple(shape)
    spacing = np.asarray(length, dtype=float) / np.asarray(shape)
    return FluidGrid(origin=np.zeros(3), spacing=spacing, shape=shape, periodic=np.array([True, True, False]))


def _solver(grid, gravity=(0.0, 0.0, 0.0), **fluid) -> NavierStokesSolver:
    config = NavierStokesFluid.model_validate({"model": "navier-stokes", "density": RHO, **fluid})
    return NavierStokesSolver(config, grid, gravity)


# ------------------------------------------------------------------------------- no forcing


@pytest.mark.parametrize("formulation", ["A", "B"])
@pytest.mark.parametrize("top", ["pressure", "no-flow"])
def test_no_forcing_stays_exactly_zero(formulation, top):
    """C: "with no forcing at all, p and v stay exactly 0" -- also with a porosity that varies in
    space (but not in time), every porosity term active, and a closed box (singular pressure
    equation). Zero right-hand sides must give exact zeros, not round-off."""
    grid = _grid((6, 5, 7), (0.06, 0.05, 0.07))
    solver = _solver(grid, formulation=formulation, top={"type": top, "no_slip": True})
    fs = solver.allocate()
    fs.phi[...] = np.random.default_rng(3).uniform(0.35, 1.0, grid.shape)
    for n in range(50):
        solver.step(fs, n * 1e-3, 1e-3)
    assert not fs.v.any() and not fs.p.any() and not fs.grad_p.any()


# ------------------------------------------------------------------------------- hydrostatics

HYDRO_TOL = 1e-10  # solver tolerance of the hydrostatic runs


@pytest.mark.parametrize(
    ("formulation", "beta", "phi"), [("A", 0.0, 1.0), ("A", 1.0, 1.0), ("A", 0.0, 0.6), ("B", 0.0, 1.0)]
)
def test_hydrostatic_column_stays_at_rest(formulation, beta, phi):
    """C: a column at rest under gravity (open at the top at 0 Pa, closed at the bottom), starting
    from p = 0 everywhere, stays at rest: |v| < 1e-9 m/s over 1000 steps, and the pressure is
    rho g (H - z) at the cell centres to the solver tolerance (relative 1e-10 of the residual;
    1e-9 of rho g H is allowed for the conditioning of a 16-cell column).

    The first step must build the whole hydrostatic pressure from nothing (beta = 0 rebuilds it
    every step, beta = 1 adds increments). With uniform phi < 1 formulation A still balances
    gravity with grad p = rho g (its pressure term is -phi grad p against phi rho g)."""
    n, height = 16, 0.1
    grid = _grid((4, 4, n), (0.025, 0.025, height))
    solver = _solver(
        grid,
        (0.0, 0.0, -G),
        formulation=formulation,
        beta=beta,
        viscosity=1e-3,
        solver={"tolerance": HYDRO_TOL},
    )
    fs = solver.allocate()
    fs.phi[...] = phi
    dt = 1e-3  # s; the viscous limit is 0.049 s
    worst = 0.0
    for step in range(1000):
        solver.step(fs, step * dt, dt)
        worst = max(worst, float(np.abs(fs.v).max()))
    assert worst < 1e-9
    exact = RHO * G * (height - grid.centres(2))
    assert np.abs(fs.p - exact[None, None, :]).max() <= 1e-9 * RHO * G * height
    np.testing.assert_allclose(fs.grad_p[..., 2], -RHO * G, rtol=1e-9)


def test_hydrostatic_pressure_follows_a_modulated_top():
    """A prescribed top pressure p_t(t) = A sin(2 pi f t) shifts the whole hydrostatic column
    with it: at every step p = p_t(t) + rho g (H - z) (the fluid is incompressible and the bottom
    is closed, so nothing flows)."""
    n, height = 8, 0.08
    grid = _grid((3, 3, n), (0.03, 0.03, height))
    top = {"type": "pressure", "pressure": 50.0, "amplitude": 200.0, "frequency": 5.0, "phase": 0.3}
    solver = _solver(grid, (0.0, 0.0, -G), top=top, solver={"tolerance": HYDRO_TOL})
    fs = solver.allocate()
    dt = 1e-3
    for step in range(100):
        solver.step(fs, step * dt, dt)
        t = (step + 1) * dt
        p_top = 50.0 + 200.0 * math.sin(2 * math.pi * 5.0 * t + 0.3)
        exact = p_top + RHO * G * (height - grid.centres(2))
        assert np.abs(fs.p - exact[None, None, :]).max() <= 1e-9 * RHO * G * height
    assert np.abs(fs.v).max() < 1e-9


# ------------------------------------------------------------------------------- shear wave

NU = 1e-3  # m^2/s, mu = 1 Pa s at rho = 1000
AMPLITUDE = 1e-3  # m/s


def _decay_rate_error(cells: int, phi: float = 1.0, formulation: str = "A") -> float:
    """Relative error of the measured decay rate of u_x = A sin(k y) against nu k^2, one
    wavelength L = 1 m on `cells` cells along y, over t = 0.2/(nu k^2), dt = 0.1 of the viscous
    limit (forward Euler's own error, ~ nu k^2 dt/2 relative, is then 0.1 (k dy)^2/16 against
    the space error (k dy)^2/12: both O(dy^2))."""
    length = 1.0
    dy = length / cells
    grid = _grid((2, cells, 3), (2 * dy, length, 3 * dy))
    solver = _solver(
        grid, viscosity=NU * RHO, formulation=formulation, bottom={"type": "no-flow"}, top={"type": "no-flow"}
    )
    fs = solver.allocate()
    fs.phi[...] = phi
    k = 2 * math.pi / length
    profile = np.sin(k * grid.centres(1))
    fs.v[..., 0] = AMPLITUDE * profile[None, :, None]
    duration = 0.2 / (NU * k * k)
    steps = math.ceil(duration / (0.1 * solver.viscous_limit()))
    dt = duration / steps
    for step in range(steps):
        solver.step(fs, step * dt, dt)
    # the discrete wave keeps its shape: project on sin(k y)
    amplitude = 2.0 / cells * float(fs.v[0, :, 1, 0] @ profile)
    assert np.abs(fs.v[..., 1:]).max() == 0.0  # a pure shear flow has no pressure and no v_y, v_z
    assert (fs.v[..., 0] == fs.v[0:1, :, 0:1, 0]).all()  # and stays uniform along x and z
    rate = -math.log(amplitude / AMPLITUDE) / duration
    return rate / (NU * k * k) - 1.0


def test_shear_wave_decays_at_the_viscous_rate_with_order_two():
    """C: decaying shear wave, rate nu k^2 within 1 % at 32 cells per wavelength, spatial order 2.

    The 3-point second difference gives the rate nu k^2 (1 - (k dy)^2/12 + ...): -0.32 % at
    32 cells; forward Euler adds +0.1 (k dy)^2/16 (0.02 %). The observed order from 16, 32 and 64
    cells must be 2 within 0.1 (the next term is O(dy^4))."""
    errors = [_decay_rate_error(n) for n in (16, 32, 64)]
    assert abs(errors[1]) < 0.01
    orders = [math.log2(errors[i] / errors[i + 1]) for i in range(2)]
    assert all(abs(order - 2.0) < 0.1 for order in orders), (errors, orders)


@pytest.mark.parametrize("formulation", ["A", "B"])
def test_shear_wave_unchanged_by_uniform_porosity(formulation):
    """C: "unchanged for uniform porosity phi < 1": (1/phi) div(phi tau) = div(tau) when phi is
    uniform, so the decay rate at phi = 0.4 is the phi = 1 rate to round-off."""
    assert _decay_rate_error(32, phi=0.4, formulation=formulation) == pytest.approx(
        _decay_rate_error(32), abs=1e-10
    )


# ------------------------------------------------------------------------------- PCG vs Jacobi


def test_pcg_and_jacobi_give_the_same_fluid_step():
    """The pressure equation solved by PCG and by the reference's Jacobi iteration, both to the
    relative residual 1e-10, gives the same corrected velocity to ~1e-8 of its scale: a flow
    through a random porosity field (formulation A, variable coefficients) driven by a
    modulated top pressure. Jacobi needs many times more iterations."""
    grid = _grid((8, 8, 8), (0.08, 0.08, 0.08))
    rng = np.random.default_rng(7)
    phi = rng.uniform(0.4, 1.0, grid.shape)
    v0 = rng.normal(0.0, 1e-3, (*grid.shape, 3))
    results = {}
    for method in ("pcg", "jacobi"):
        solver = _solver(
            grid,
            (0.0, 0.0, -G),
            top={"type": "pressure", "pressure": 10.0},
            solver={"method": method, "tolerance": 1e-10},
        )
        fs = solver.allocate()
        fs.phi[...] = phi
        fs.v[...] = v0
        result = solver.step(fs, 0.0, 1e-3)
        results[method] = (fs.v.copy(), fs.p.copy(), result.iterations)
    (v_pcg, p_pcg, it_pcg), (v_jac, p_jac, it_jac) = results["pcg"], results["jacobi"]
    scale = float(np.abs(v_pcg).max())
    assert np.abs(v_pcg - v_jac).max() < 1e-7 * scale
    assert np.abs(p_pcg - p_jac).max() < 1e-7 * float(np.abs(p_pcg).max())
    assert it_jac > 5 * it_pcg
