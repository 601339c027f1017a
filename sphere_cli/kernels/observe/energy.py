"""Energies of the particle system, for observables and blow-up checks (not in the time loop).

kinetic: sum m v^2/2 + I w^2/2; potential: -sum m g.x; elastic: normal k_n delta^2/2 (linear) or
(2/5) k_h delta^{5/2} (Hertz, the work of (4/3) E* sqrt(R*) delta^{3/2}) plus tangential
k_t |xi|^2/2 per contact; the half neighbour list holds each pair once.
Arguments as in contact.py / walls.py (table (M,M,6), wall_table (W,M,6)). Sums are serial, in
particle order, so results do not depend on the thread count.
"""

import math

from numba import njit

from ..laws import HERTZ_MINDLIN, K_N, K_T
from ..neighbors import minimum_image


@njit(cache=True)
def kinetic_energy(vel, angvel, mass, inertia):
    total = 0.0
    for i in range(vel.shape[0]):
        v2 = vel[i, 0] ** 2 + vel[i, 1] ** 2 + vel[i, 2] ** 2
        w2 = angvel[i, 0] ** 2 + angvel[i, 1] ** 2 + angvel[i, 2] ** 2
        total += 0.5 * (mass[i] * v2 + inertia[i] * w2)
    return total


@njit(cache=True)
def potential_energy(pos, mass, body_acc):
    total = 0.0
    for i in range(pos.shape[0]):
        total -= mass[i] * (body_acc[0] * pos[i, 0] + body_acc[1] * pos[i, 1] + body_acc[2] * pos[i, 2])
    return total


@njit(cache=True, inline="always")
def _elastic(row, law, delta, r_eff, xi2):
    """Normal plus tangential elastic energy of one contact [J]: linear k_n delta^2/2, Hertz
    (2/5) k_h delta^{5/2} = (2/5) K_N s delta^2 with s = sqrt(R* delta); tangential k_t |xi|^2/2."""
    if law == HERTZ_MINDLIN:
        s = math.sqrt(r_eff * delta)
        return 0.4 * row[K_N] * s * delta * delta + 0.5 * row[K_T] * s * xi2
    return 0.5 * (row[K_N] * delta * delta + row[K_T] * xi2)


@njit(cache=True)
def pair_elastic_energy(pos, radius, material, nbr, nbr_count, start, hist, table, law, length, periodic):
    """Returns (elastic energy [J], number of touching pairs)."""
    total = 0.0
    touching = 0
    cap = nbr.shape[1]
    single = table.shape[0] == 1
    for i in range(pos.shape[0]):
        for k in range(min(nbr_count[i], cap)):
            j = nbr[i, k]
            d2 = 0.0
            for a in range(3):
                d = minimum_image(pos[i, a] - pos[j, a], length[a], periodic[a])
                d2 += d * d
            reach = radius[i] + radius[j]
            if d2 < reach * reach:
                delta = reach - d2**0.5
                s = start[i] + k
                xi2 = 0.0  # no springs without friction
                if hist.shape[0] > 0:
                    xi2 = hist[s, 0] ** 2 + hist[s, 1] ** 2 + hist[s, 2] ** 2
                row = table[0, 0] if single else table[material[i], material[j]]
                r_eff = radius[i] * radius[j] / reach
                total += _elastic(row, law, delta, r_eff, xi2)
                touching += 1
    return total, touching


@njit(cache=True)
def wall_elastic_energy(
    pos, radius, inv_mass, material, wall_axis, wall_sign, wall_coord, wall_table, wall_hist, law
):
    """Returns (elastic energy [J], number of particle-wall contacts). Particles with inv_mass = 0
    (fixed, prescribed, glued to a wall) do not touch walls (kernels/walls.py)."""
    total = 0.0
    touching = 0
    single = wall_table.shape[1] == 1
    for i in range(pos.shape[0]):
        if inv_mass[i] == 0.0:
            continue
        for w in range(wall_axis.shape[0]):
            gap = wall_sign[w] * (pos[i, wall_axis[w]] - wall_coord[w])
            if gap < radius[i]:
                delta = radius[i] - gap
                xi2 = 0.0
                if wall_hist.shape[0] > 0:
                    xi2 = wall_hist[i, w, 0] ** 2 + wall_hist[i, w, 1] ** 2 + wall_hist[i, w, 2] ** 2
                row = wall_table[w, 0] if single else wall_table[w, material[i]]
                total += _elastic(row, law, delta, radius[i], xi2)
                touching += 1
    return total, touching
