"""One contact seen from one of its particles, for measurements (stress, energy budget): the
geometry and relative velocities that kernels/contact.py and kernels/walls.py feed into their
law, so that a measurement can call the same law functions (normal_law, tangential_force,
rolling_torque) on the same inputs and get the same forces, without touching the springs.

Conventions as in contact.py: n points from j to i (from the wall into the box); the contact
point of i is x_i - r_i n; relative velocity of the contact point of i with respect to j (or the
wall, moving at wall_vel): v_i - v_j - (r_i w_i + r_j w_j) x n.
Arguments: pos, vel, angvel (N,3) [m, m/s, rad/s]; radius (N,) [m]; length (3,) [m], periodic
(3,) uint8; wall_axis (W,) int64, wall_sign (W,) +1 lower / -1 upper face, wall_coord (W,) [m],
wall_vel (W,3) [m/s].
"""

import math

import numpy as np
from numba import njit

from .neighbors import minimum_image


@njit(cache=True, inline="always")
def pair_normal(pos, radius, i, j, length, periodic):
    """(touching, n0, n1, n2, overlap delta [m]) of particles i and j."""
    d0 = minimum_image(pos[i, 0] - pos[j, 0], length[0], periodic[0])
    d1 = minimum_image(pos[i, 1] - pos[j, 1], length[1], periodic[1])
    d2 = minimum_image(pos[i, 2] - pos[j, 2], length[2], periodic[2])
    dist2 = d0 * d0 + d1 * d1 + d2 * d2
    reach = radius[i] + radius[j]
    if dist2 >= reach * reach:
        return False, 0.0, 0.0, 0.0, 0.0
    dist = math.sqrt(dist2)
    inv = 1.0 / dist
    return True, d0 * inv, d1 * inv, d2 * inv, reach - dist


@njit(cache=True, inline="always")
def wall_normal(pos, radius, i, w, wall_axis, wall_sign, wall_coord):
    """(touching, n0, n1, n2, overlap delta [m]) of particle i and wall w."""
    a = np.uint64(wall_axis[w])  # unsigned: no negative-index wraparound code (the wall kernel's hot loop)
    gap = wall_sign[w] * (pos[i, a] - wall_coord[w])
    ri = radius[i]
    if gap >= ri:
        return False, 0.0, 0.0, 0.0, 0.0
    n0 = wall_sign[w] if a == 0 else 0.0
    n1 = wall_sign[w] if a == 1 else 0.0
    n2 = wall_sign[w] if a == 2 else 0.0
    return True, n0, n1, n2, ri - gap


@njit(cache=True, inline="always")
def pair_slip(vel, angvel, i, j, ri, rj, n0, n1, n2):
    """Relative velocity of the contact point of i with respect to j (3 values) [m/s]."""
    s0 = ri * angvel[i, 0] + rj * angvel[j, 0]
    s1 = ri * angvel[i, 1] + rj * angvel[j, 1]
    s2 = ri * angvel[i, 2] + rj * angvel[j, 2]
    return (
        (vel[i, 0] - vel[j, 0]) - (s1 * n2 - s2 * n1),
        (vel[i, 1] - vel[j, 1]) - (s2 * n0 - s0 * n2),
        (vel[i, 2] - vel[j, 2]) - (s0 * n1 - s1 * n0),
    )


@njit(cache=True, inline="always")
def wall_slip(vel, angvel, i, ri, n0, n1, n2, wv0, wv1, wv2):
    """Relative velocity of the contact point of i with respect to a wall moving at wv [m/s]."""
    s0 = ri * angvel[i, 0]
    s1 = ri * angvel[i, 1]
    s2 = ri * angvel[i, 2]
    return (
        vel[i, 0] - wv0 - (s1 * n2 - s2 * n1),
        vel[i, 1] - wv1 - (s2 * n0 - s0 * n2),
        vel[i, 2] - wv2 - (s0 * n1 - s1 * n0),
    )
