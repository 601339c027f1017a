"""The self-induced velocity of a particle on the Navier-Stokes grid: how fast the fluid of its
cell moves because the particle pushes on it, which the particle must not count as the fluid it
moves through.

A particle smaller than its cell hands its drag to the fluid of that one cell; the cell's
velocity then holds the particle's own disturbance, and a drag law evaluated with it (the laws
take the undisturbed velocity: Stokes drag as phi -> 1) is too weak, so a sphere settling alone
falls too fast, in creeping flow by 3 pi alpha d/dx of its velocity once the disturbance is
steady (30 % on cells of 4 d). This is the self-induced velocity of two-way coupled
point-particle methods (Horwitz & Mani 2016, J. Comput. Phys. 318, 85; Balachandar, Liu &
Lakhote 2019, J. Comput. Phys. 376, 160). The drag module subtracts an estimate u' of it from the
cell velocity each particle feels.

Response of the grid. A force F in one cell (its two faces of each component take half,
kernels/fluid/navier_stokes.py `predict`), read back as the cell velocity (the mean of those two
faces), moves the cell's fluid of an unbounded grid in creeping flow, from rest, at
    u_c(t) = F_c / mu  sum over modes  w (1 - exp(-nu lambda t)),
a sum over the Fourier modes of the MAC Stokes operator (its Laplacian and projection are exact
there: s_i = 2 sin(theta_i/2)/dx_i, lambda = sum s_i^2, the filter of the two faces cos^2(theta_c/2)):
    w d^3theta = 1/V_cell  cos^2(theta_c/2) (1 - s_c^2/lambda) / lambda  d^3theta/(2 pi)^3
over theta in [-pi, pi]^3. Its steady value alpha_c = sum w is 0.12637/dx on cubic cells; its
slow approach (the t^-1/2 tail of diffusion: 0.75 of alpha at t = dx^2/nu, 0.93 at 10 dx^2/nu)
is why the modes are kept. They are grouped in MODES bands of lambda, a factor 4 apart below
the largest, each with its weight W_j (the band's share of alpha) and one rate lambda_j (its
w-weighted mean, so that the initial response, sum W_j lambda_j = beta_c, 0.39508 on cubic
cells, is exact); the band from 0, which the quadrature cannot resolve, takes the rest of alpha
at lambda_0 = (its top)/3, the mean of a continuum band. This step response differs from the
mode integral by under 0.015 of alpha at any time. The box, walls and other particles add a
smooth, physical part to the response (a periodic array of spheres settles slower, Hasimoto
1959); only this local part of an unbounded grid is the artifact.

Dynamics. Each particle carries the disturbance of each band, driven by its drag F over a step:
    du'_j/dt = -nu (lambda_j + kappa^2) (u'_j + W_j s_j^2 F / mu),
    s_j = lambda_j / (lambda_j + kappa^2),   kappa^2 = S / (mu V_cell),
S = sum K_q the drag coefficients of the other particles of the cell [kg/s]: they resist the
fluid's motion (Brinkman screening: each band decays faster by S/(rho V_cell)); S is the sum of
the current K of the cell's particles less the particle's own. The response is
that of clear fluid: the porosity of the particle's cell, lowered by the particle itself, is not
what its wake spreads through (taking it, 1/phi, overcorrects a sphere of half the cell by 8 %). The factor
s_j is squared so that a particle alone in its cell (s = 1) sees the whole response of the
grid, while in a cell of N particles (a bed, where the laws are closures on the cell's mean
velocity, which rightly holds every particle's share) the correction falls as s_j^2, as 1/N^2
once the others' drag dominates (kappa^2 above the bands' rates): that blend is a modelling
choice, not derived. A particle nearly as wide as its cell would take back more than half of
its own drag (loop gain K sum W s^2/mu > 1/2, about d/dx > 0.4 alone): its correction is scaled
down to that half (kernels/fluid/drag.py, GAIN_CAP), so the drag stays bounded. The quadrature
is meant for cells of aspect ratio up to about 10 (flatter cells put most of alpha into the
unresolved band).
"""

from __future__ import annotations

import numpy as np

from ...kernels.fluid.drag import BANDS

MODES = BANDS  # bands of lambda: [0, e_1], then a factor 4 each up to the largest (the kick's)


def _bands(spacing: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Midpoint rule with n points per axis over [0, pi]^3 (the integrands are even in each
    theta_i): per component c and band j the sums of w and of w lambda (3, MODES), and alpha
    (3,) over all bands [1/m]."""
    theta = (np.arange(n) + 0.5) * (np.pi / n)
    grids = np.meshgrid(theta, theta, theta, indexing="ij", sparse=True)
    s2 = [(2.0 * np.sin(t / 2.0) / h) ** 2 for t, h in zip(grids, spacing, strict=True)]
    lam = s2[0] + s2[1] + s2[2]
    top = float(np.sum(4.0 / spacing**2))
    band = np.searchsorted(top * 4.0 ** np.arange(1 - MODES, 1), lam).ravel()
    scale = 1.0 / (n**3 * float(np.prod(spacing)))
    weight = np.empty((3, MODES))
    slope = np.empty((3, MODES))
    for c in range(3):
        filtered = np.broadcast_to(np.cos(grids[c] / 2.0) ** 2 * (1.0 - s2[c] / lam), lam.shape).ravel()
        weight[c] = np.bincount(band, weights=filtered / lam.ravel(), minlength=MODES) * scale
        slope[c] = np.bincount(band, weights=filtered, minlength=MODES) * scale
    return weight, slope, weight.sum(axis=1)


def lattice_modes(spacing) -> tuple[np.ndarray, np.ndarray]:
    """Band weights W (3, MODES) [1/m] (summing to alpha_c) and rates lambda (3, MODES) [1/m^2]
    of the module docstring for cells of the given spacing (3,) [m]. alpha's 1/lambda
    singularity makes the midpoint rule converge as 1/n; a Richardson step from n = 32 and 64
    leaves under 1e-5 relative, and the band from 0 takes the difference."""
    spacing = np.asarray(spacing, dtype=np.float64)
    _, _, coarse = _bands(spacing, 32)
    weight, slope, fine = _bands(spacing, 64)
    rate = np.empty_like(weight)
    rate[:, 1:] = slope[:, 1:] / weight[:, 1:]
    weight[:, 0] = (2.0 * fine - coarse) - weight[:, 1:].sum(axis=1)
    rate[:, 0] = float(np.sum(4.0 / spacing**2)) * 4.0 ** (1 - MODES) / 3.0
    return weight, rate
