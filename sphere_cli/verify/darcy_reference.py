"""Analytic solutions the Darcy tests and `sphere verify` compare with, and a small helper that
builds the fluid alone (physics/pore_pressure.PorePressure) on a column of cells.

Terzaghi (1943) one-dimensional consolidation, as in Verruijt, Soil Mechanics (2012), ch. 15:
a layer of height H drained at the top (p = 0), impermeable at the base, initial excess
pressure p0, D = k / (beta_f phi mu) (the fluid's storage alone: a rigid skeleton),
T = D t / H^2, z' the depth below the drained top:

    p(z', t) = sum_m (2 p0 / M) sin(M z' / H) exp(-M^2 T),   M = (2m + 1) pi / 2,
    U(T)     = 1 - sum_m (2 / M^2) exp(-M^2 T).

Periodic pressure on the top of a layer (Carslaw & Jaeger, Conduction of Heat in Solids, 1959,
sec. 2.6 for the half-space): top p = A sin(omega t), no flow at the base z = 0, height H:
p(z, t) = Im[A cosh(lambda z) / cosh(lambda H) exp(i omega t)], lambda = (1 + i) / delta,
skin depth delta = sqrt(2 D / omega); for H >> delta the amplitude at depth d below the top is
A exp(-d / delta) and the lag d / delta.
"""

from __future__ import annotations

import numpy as np

from sphere_cli.config.fluid_darcy import DarcyFluid
from sphere_cli.physics.fluid.grid import FluidGrid
from sphere_cli.physics.fluid.pore_pressure import PorePressure

# shared: water, a fine sand [SI]
VISCOSITY = 1.0e-3
COMPRESSIBILITY = 4.5e-10
POROSITY = 0.4


def terzaghi_modes(terms: int = 2000) -> np.ndarray:
    return np.pi * (2 * np.arange(terms) + 1) / 2


def terzaghi_pressure(depth: np.ndarray, T: float, p0: float, H: float) -> np.ndarray:
    M = terzaghi_modes()
    return (2 * p0 / M * np.sin(np.outer(depth / H, M)) * np.exp(-(M**2) * T)).sum(axis=1)


def terzaghi_consolidation(T: float) -> float:
    M = terzaghi_modes()
    return float(1.0 - (2.0 / M**2 * np.exp(-(M**2) * T)).sum())


def periodic_top_pressure(z: np.ndarray, H: float, A: float, delta: float) -> np.ndarray:
    """Complex amplitude of the periodic state (multiply by exp(i omega t), take Im)."""
    lam = (1 + 1j) / delta
    return A * np.cosh(lam * z) / np.cosh(lam * H)


def column(nz: int, height: float, fluid: dict, cells_xy=(1, 1), periodic_xy=(False, False)) -> PorePressure:
    """The fluid alone on nx x ny x nz cubic cells filling a column of this height (the z axis
    bounded), with the porosity POROSITY everywhere; `fluid` holds the [fluid] keys."""
    h = height / nz
    config = DarcyFluid.model_validate(
        {
            "model": "darcy",
            "viscosity": VISCOSITY,
            "compressibility": COMPRESSIBILITY,
            "solver": {"tolerance": 1e-12},  # solve far below the discretisation errors measured
            **fluid,
        }
    )
    grid = FluidGrid(
        origin=np.zeros(3),
        spacing=np.array([h, h, h]),
        shape=(cells_xy[0], cells_xy[1], nz),
        periodic=np.array([periodic_xy[0], periodic_xy[1], False]),
    )
    model = PorePressure(config, grid)
    model.state.porosity[...] = POROSITY
    return model
