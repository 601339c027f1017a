"""Energies of the particle system, for observables and blow-up checks (not in the time loop).

kinetic: sum m v^2/2 + I w^2/2; potential: -sum m g.x; elastic (linear contact):
normal k_n delta^2/2 plus tangential k_t |xi|^2/2 per pair, each pair seen from both sides and
so halved; walls count once. Arguments as in contact.py / walls.py. Sums are serial, in
particle order, so results do not depend on the thread count.
"""

from numba import njit

from .neighbors import minimum_image


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


@njit(cache=True)
def linear_pair_elastic_energy(pos, radius, nbr, nbr_count, hist, kn, kt, length, periodic):
    """Returns (elastic energy [J], number of touching pairs)."""
    total = 0.0
    touching = 0
    cap = nbr.shape[1]
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
                xi2 = hist[i, k, 0] ** 2 + hist[i, k, 1] ** 2 + hist[i, k, 2] ** 2
                total += 0.25 * (kn * delta * delta + kt * xi2)
                if j > i:
                    touching += 1
    return total, touching


@njit(cache=True)
def linear_wall_elastic_energy(pos, radius, wall_axis, wall_sign, wall_coord, wall_hist, kn, kt):
    """Returns (elastic energy [J], number of particle-wall contacts)."""
    total = 0.0
    touching = 0
    for i in range(pos.shape[0]):
        for w in range(wall_axis.shape[0]):
            gap = wall_sign[w] * (pos[i, wall_axis[w]] - wall_coord[w])
            if gap < radius[i]:
                delta = radius[i] - gap
                xi2 = wall_hist[i, w, 0] ** 2 + wall_hist[i, w, 1] ** 2 + wall_hist[i, w, 2] ** 2
                total += 0.5 * (kn * delta * delta + kt * xi2)
                touching += 1
    return total, touching
