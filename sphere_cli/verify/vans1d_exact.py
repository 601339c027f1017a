"""Exact steady solutions of the 1D fluid momentum balance (verification group C), for the tests
and `sphere verify`.

Turbulent free-surface flow with a mixing length l(s) and molecular viscosity nu: the shear stress
is rho u*^2 (1 - s/H) at height s, so (nu + l^2 |u'|) u' = u*^2 (1 - s/H) and, taking the positive
root in the form free of cancellation,
    u'(s) = 2 tau / (nu + sqrt(nu^2 + 4 l^2 tau)),  tau = u*^2 (1 - s/H),
integrated here by 12-point Gauss-Legendre on 3000 geometric sub-intervals (relative error below
1e-12, far under the discretisation errors the tests measure).

Through a solid fraction c(s) (no drag: the fluid equation's (1 - c) factors and Li & Sawamoto's
mixing length l = kappa int_0^s (1 - c/c_max) ds' alone), the balance of the stress with the
weight of the fluid above gives (1 - c) (nu + l^2 |u'|) u' = g sin(alpha) int_s^H (1 - c) ds', so
tau = that / (1 - c). With the smooth bed c = c0 (1 - tanh((s - s_b)/w))/2 both integrals of c
have closed forms (ln cosh).
"""

from __future__ import annotations

import numpy as np

G = 9.81
SLOPE = 0.05  # rad
DEPTH = 0.1  # m
NU = 1.0e-6  # m^2/s
KAPPA = 0.41
U_STAR = float(np.sqrt(G * np.sin(SLOPE) * DEPTH))  # 0.2214 m/s


# the smooth bed of the Li-Sawamoto case: solid fraction c0 below s_b, clear water above
BED_SOLID, BED_TOP, BED_WIDTH, PACKED = 0.5, 0.03, 0.01, 0.61  # [-], [m], [m], [-]


def bed_solid(s):
    """c(s) = c0 (1 - tanh((s - s_b)/w))/2."""
    return 0.5 * BED_SOLID * (1.0 - np.tanh((np.asarray(s, dtype=float) - BED_TOP) / BED_WIDTH))


def _log_cosh(x):
    x = np.abs(x)
    return x + np.log1p(np.exp(-2.0 * x)) - np.log(2.0)


def bed_solid_integral(s):
    """int_0^s c(s') ds' [m]."""
    s = np.asarray(s, dtype=float)
    shift = _log_cosh((s - BED_TOP) / BED_WIDTH) - _log_cosh(-BED_TOP / BED_WIDTH)
    return 0.5 * BED_SOLID * (s - BED_WIDTH * shift)


def mixing_length(kind: str, s, depth=DEPTH, kappa=KAPPA, a_plus=0.0, u_star=U_STAR, nu=NU, sublayer=0.0):
    """Prandtl, parabolic or Li-Sawamoto (over the bed of bed_solid) mixing length, damped by van
    Driest's factor when a_plus > 0, and zero below the height `sublayer` [m] (YADE's viscous
    sublayer)."""
    s = np.asarray(s, dtype=float)
    if kind == "prandtl":
        ell = kappa * s
    elif kind == "li-sawamoto":
        ell = kappa * (s - bed_solid_integral(s) / PACKED)
    elif kind == "parabolic":
        ell = kappa * s * np.sqrt(np.maximum(0.0, 1.0 - s / depth))
    else:
        raise ValueError(kind)
    if a_plus > 0.0:
        ell = ell * (1.0 - np.exp(-ell / kappa * u_star / (a_plus * nu)))
    return np.where(s < sublayer, 0.0, ell)


def velocity_gradient(kind: str, s, u_star=U_STAR, depth=DEPTH, nu=NU, a_plus=0.0, sublayer=0.0):
    s = np.asarray(s, dtype=float)
    if kind == "li-sawamoto":  # the fluid's weight above s through the bed, per fluid area
        above = (depth - s) - (bed_solid_integral(depth) - bed_solid_integral(s))
        tau = u_star**2 / depth * above / (1.0 - bed_solid(s))
    else:
        tau = u_star**2 * (1.0 - s / depth)
    ell = mixing_length(kind, s, depth, a_plus=a_plus, u_star=u_star, nu=nu, sublayer=sublayer)
    return 2.0 * tau / (nu + np.sqrt(nu * nu + 4.0 * ell * ell * tau))


def free_surface_velocity(kind: str, s, u_star=U_STAR, depth=DEPTH, nu=NU, a_plus=0.0, sublayer=0.0):
    """u(s) of the steady turbulent free-surface flow of the mixing-length model `kind` (with
    van Driest's damping of constant a_plus when it is > 0, no eddy viscosity below `sublayer`;
    its jump is a node of the quadrature)."""
    x, w = np.polynomial.legendre.leggauss(12)
    nodes = np.concatenate([[0.0], np.geomspace(1e-10 * depth, depth, 3000)])
    if sublayer > 0.0:
        nodes = np.unique(np.concatenate([nodes, [sublayer]]))

    def integral(a, b):
        mid, half = 0.5 * (a + b), 0.5 * (b - a)
        pts = mid[:, None] + half[:, None] * x[None, :]
        return half * (velocity_gradient(kind, pts, u_star, depth, nu, a_plus, sublayer) @ w)

    cumulative = np.concatenate([[0.0], np.cumsum(integral(nodes[:-1], nodes[1:]))])
    s = np.asarray(s, dtype=float)
    i = np.clip(np.searchsorted(nodes, s) - 1, 0, nodes.size - 2)
    return cumulative[i] + integral(nodes[i], s)
