"""Ergun pressure drop through a fixed bed of imposed uniform porosity (verification group D):
the Navier-Stokes solver with the cell-averaged drag of kernels/fluid/drag.py (cell_drag).

Ergun (1952): dP/L = 150 mu (1-eps)^2 U/(eps^3 d^2) + 1.75 rho (1-eps) U^2/(eps^3 d), U the
superficial velocity, eps the porosity, d the particle diameter.
"""

from __future__ import annotations

import numpy as np
import pytest

from sphere_cli.config.fluid_navier_stokes import NavierStokesFluid
from sphere_cli.kernels.fluid.drag import GIDASPOW, cell_drag
from sphere_cli.physics.fluid.grid import FluidGrid
from sphere_cli.physics.fluid.navier_stokes import NavierStokesSolver

RHO, MU, D = 1000.0, 1e-3, 1e-3  # water, 1 mm spheres


def ergun(eps, superficial):
    """Ergun's pressure gradient [Pa/m] at porosity eps and superficial velocity U [m/s]."""
    return 150.0 * MU * (1 - eps) ** 2 * superficial / (eps**3 * D**2) + 1.75 * RHO * (
        1 - eps
    ) * superficial**2 / (eps**3 * D)


@pytest.mark.parametrize("formulation", ["A", "B"])
@pytest.mark.parametrize("eps", [0.4, 0.7])
def test_ergun_pressure_drop_with_imposed_porosity(formulation, eps):
    """D: upward flow driven by a pressure difference between the bottom and top boundaries
    through a bed (cells 10-29 of 40, porosity eps; clear fluid around) of 1 mm spheres held
    still, no gravity. At steady state (600 steps of 0.2 ms, ~20 relaxation times of the column):
    - the pressure gradient inside the bed equals Ergun's at the superficial velocity U (the mean
      flux phi_f v_f through its faces) within 1 % (validation D; measured 1e-10: the drag, implicit
      in the fluid, is exactly Ergun's at the faces' flux inside the uniform bed);
    - the force the fluid exerts on the bed (the exchange the fluid steps took, drag plus
      pressure-gradient force) equals the pressure drop between the boundaries times the area
      within 1 % (measured 5e-5: the clear fluid either side of the bed has no losses and the
      same momentum flux in and out, so nothing else acts on the column).
    Both formulations: in A the fluid's -phi grad p carries the reaction of the pressure-gradient
    force, in B the exchange does; the physics is the same."""
    nz, dz = 40, 1e-3
    spacing = np.array([1e-3, 1e-3, dz])
    grid = FluidGrid(
        origin=np.zeros(3), spacing=spacing, shape=(2, 2, nz), periodic=np.array([1, 1, 0], bool)
    )
    config = NavierStokesFluid.model_validate(
        {
            "model": "navier-stokes",
            "density": RHO,
            "viscosity": MU,
            "formulation": formulation,
            "bottom": {"type": "pressure", "pressure": 150.0},
            "top": {"type": "pressure", "pressure": 0.0},
        }
    )
    solver = NavierStokesSolver(config, grid, (0.0, 0.0, 0.0))
    fs = solver.allocate()
    bed = slice(10, 30)
    fs.porosity[:, :, bed] = eps
    diameter = np.full(grid.shape, D)
    at_rest = np.zeros((grid.cell_count, 3))  # the bed's velocity
    solver.initial_pressure(fs, 0.0)
    dt = 2e-4
    for n in range(600):
        cell_drag(
            GIDASPOW, RHO, MU, 0.1, fs.v.reshape(-1, 3), fs.porosity.reshape(-1), diameter.reshape(-1),
            at_rest, fs.grad_p.reshape(-1, 3), formulation == "B", fs.f_i.reshape(-1, 3),
            fs.k_drag.reshape(-1),
        )  # fmt: skip
        solver.step(fs, n * dt, dt)
    # the discrete flux through the face between cells k - 1 and k: phi_f v_f
    phi = fs.porosity[0, 0, :]
    flux = 0.5 * (phi[1:] + phi[:-1]) * fs.v_face[0, 0, 1:-1, 2]
    superficial = flux[13:27].mean()  # through the bed, away from its ends
    gradient = (fs.p[0, 0, 13] - fs.p[0, 0, 27]) / (14 * dz)
    assert gradient == pytest.approx(ergun(eps, superficial), rel=0.01)
    drop = 150.0  # between the boundaries: the clear fluid either side carries the same momentum
    on_bed = fs.f_exchange[:, :, bed, 2].sum() * grid.cell_volume  # what the fluid step took
    if formulation == "A":
        on_bed += -((1 - eps) * fs.grad_p[:, :, bed, 2]).sum() * grid.cell_volume
    area = 2 * 2 * 1e-6
    assert on_bed == pytest.approx(drop * area, rel=0.01)
