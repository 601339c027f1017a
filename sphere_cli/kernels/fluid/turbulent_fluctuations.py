"""Turbulent velocity fluctuations seen by the particles of a vans1d fluid: a discrete random walk
(YADE HydroForceEngine::turbulentFluctuationZDep; Maurin et al. 2015, Phys. Fluids 27, 113302).

Each selected particle above the bed keeps a fluctuation (u', v', w') for an eddy lifetime, then
draws a new one: w' = r1 u*_l, v' = r2 u*_l, u' = r3 u*_l with r1, r2, r4 standard normal and
r3 = -r1 + r4 (correlated: <u'w'> = -u*_l^2 = -R_xz/rho, <u'^2> = 2 u*_l^2, as the Reynolds
stress and Nezu's measurements ask) or r3 = r4 (independent). u*_l = sqrt(R_xz/rho) with R_xz the
Reynolds shear stress rho (1 - c) nu_t du/dz interpolated at the particle's height between the
layer faces. Lifetime 0.33 kappa z_b / u*_l, z_b = max(z - bed, 11.6 nu / u*_l), at most 10 s.
Below the bed, above the surface or where R_xz <= 0 the fluctuation is zero and drawn again at
the next call.

The normals come from a counter-based generator: the k-th uniform of a particle's n-th draw is
a hash (splitmix64) of (seed, particle, n, k), so the sequence of each particle depends on
nothing else: results do not depend on the thread count, and a resume that restores the
counters continues the same sequence.

Arguments: pos (N,3) [m]; key (N,) int64, the number of each particle's sequence (its index
in the scene: on an MPI rank, the global index of each particle it holds); selected (N,) uint8;
faces (n+1,) [m]; reynolds (n+1,) [Pa] at the faces; rho [kg/m^3]; nu [m^2/s]; kappa [-];
bed [m]; seed uint64; correlated (bool); elapsed [s] since the last call; fluct (N,3) [m/s],
lifetime (N,) [s] and draws (N,) uint64, updated.
"""

import math

import numpy as np
from numba import njit, prange

from .profile_forces import bracket

GOLDEN = np.uint64(0x9E3779B97F4A7C15)
MIX_1 = np.uint64(0xBF58476D1CE4E5B9)
MIX_2 = np.uint64(0x94D049BB133111EB)
LONGEST = 10.0  # [s] cap of a lifetime
EDDY = 0.33  # lifetime 0.33 kappa z_b / u*: the eddy turnover time of the k-epsilon model
SUBLAYER = 11.6  # z+ below which a fluctuation's depth is not taken smaller


@njit(cache=True, inline="always")
def _mix(x):
    """splitmix64's finaliser: a bijection of uint64 that spreads every input bit."""
    x = (x ^ (x >> np.uint64(30))) * MIX_1
    x = (x ^ (x >> np.uint64(27))) * MIX_2
    return x ^ (x >> np.uint64(31))


@njit(cache=True, inline="always")
def uniform(seed, particle, draw, k):
    """A uniform number in (0, 1), a fixed function of its four uint64 arguments."""
    x = _mix(seed * GOLDEN + particle)
    x = _mix(x + draw * GOLDEN)
    x = _mix(x + k)
    return (np.float64(x >> np.uint64(12)) + 0.5) * (1.0 / 4503599627370496.0)  # 52 bits, exact


@njit(cache=True, inline="always")
def _normal_pair(seed, particle, draw, k):
    """Two independent standard normals (Box-Muller) from the uniforms k and k + 1."""
    radius = math.sqrt(-2.0 * math.log(uniform(seed, particle, draw, k)))
    angle = 2.0 * math.pi * uniform(seed, particle, draw, k + np.uint64(1))
    return radius * math.cos(angle), radius * math.sin(angle)


@njit(cache=True, parallel=True)
def turbulent_fluctuations(
    pos,
    key,
    selected,
    faces,
    reynolds,
    rho,
    nu,
    kappa,
    bed,
    seed,
    correlated,
    elapsed,
    fluct,
    lifetime,
    draws,
):
    top = faces[faces.shape[0] - 1]
    for i in prange(pos.shape[0]):
        if not selected[i]:
            continue
        lifetime[i] -= elapsed
        if lifetime[i] > 0.0:
            continue
        z = pos[i, 2]
        stress = 0.0
        if bed < z < top:
            lo, hi, w = bracket(faces, z)
            stress = (1.0 - w) * reynolds[lo] + w * reynolds[hi]
        if stress <= 0.0:
            fluct[i, 0] = 0.0
            fluct[i, 1] = 0.0
            fluct[i, 2] = 0.0
            lifetime[i] = 0.0
            continue
        u_star = math.sqrt(stress / rho)
        r1, r2 = _normal_pair(seed, np.uint64(key[i]), draws[i], np.uint64(0))
        r4, _ = _normal_pair(seed, np.uint64(key[i]), draws[i], np.uint64(2))
        draws[i] += np.uint64(1)
        r3 = r4 - r1 if correlated else r4
        fluct[i, 0] = r3 * u_star
        fluct[i, 1] = r2 * u_star
        fluct[i, 2] = r1 * u_star
        depth = max(z - bed, SUBLAYER * nu / u_star)
        lifetime[i] = min(EDDY * kappa * depth / u_star, LONGEST)
