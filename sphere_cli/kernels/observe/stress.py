"""Granular stress (observables only, never in the time loop): the moment of the contact forces
on each particle, and the sums per horizontal layer.

Per particle (Love-Weber; Christoffersen, Mehrabadi & Nemat-Nasser 1981, J. Appl. Mech. 48:339):
    M_i = sum over the contacts c of i of (x_c - x_i) (x) f_c        [N m]
with x_c - x_i = -r_i n (n from the other body to i) and f_c the contact force on i (normal and
tangential, with the dashpots); for j, x_c - x_j = r_j n and the force is -f_c, so its moment is
the same expression with r_j. The forces are evaluated with the law of kernels/laws.py and
kernels/walls.py on the current state (the springs as stored, no growth), on a scratch copy of
each spring: they are the forces of the last force evaluation.
The stress of a region of volume V, compression positive, is
    sigma = -(1/V) sum_i M_i + (1/V) sum_i m_i v'_i (x) v'_i,
v' the velocity relative to the mean velocity of the particle's layer (kinetic part).

Arguments as in contact.py and contact_probe.py; inv_mass (N,) [1/kg]; wall_vel (W,3) the
walls' predicted velocities (their dashpots act on them) [m/s]; scratch (N,1,3) [m]; moment out
(N,3,3) [N m].
"""

import math

from numba import njit

from ..contact_probe import pair_normal, pair_slip, wall_normal, wall_slip
from ..laws import D_N, D_T, K_N, K_T, MU, normal_law, reduced, tangential_force


@njit(cache=True, inline="always")
def _add_moment(moment, i, ri, n0, n1, n2, f0, f1, f2):
    b0 = -ri * n0
    b1 = -ri * n1
    b2 = -ri * n2
    moment[i, 0, 0] += b0 * f0
    moment[i, 0, 1] += b0 * f1
    moment[i, 0, 2] += b0 * f2
    moment[i, 1, 0] += b1 * f0
    moment[i, 1, 1] += b1 * f1
    moment[i, 1, 2] += b1 * f2
    moment[i, 2, 0] += b2 * f0
    moment[i, 2, 1] += b2 * f1
    moment[i, 2, 2] += b2 * f2


@njit(cache=True)
def contact_moments(
    pos,
    vel_pred,
    angvel_pred,
    radius,
    mass,
    inv_mass,
    material,
    nbr,
    nbr_count,
    start,
    hist,
    table,
    law,
    length,
    periodic,
    wall_axis,
    wall_sign,
    wall_coord,
    wall_vel,
    wall_table,
    wall_hist,
    scratch,
    moment,
):
    """moment[i] = sum over the pair and wall contacts of i of (x_c - x_i) (x) f_c. Serial over
    the half list (each pair once, added to both its particles), in particle order."""
    n = pos.shape[0]
    cap = nbr.shape[1]
    single = table.shape[0] == 1
    wall_single = wall_table.shape[1] == 1
    moment[...] = 0.0
    for i in range(n):
        ri = radius[i]
        mi = mass[i]
        ci = 0 if single else material[i]
        for k in range(min(nbr_count[i], cap)):
            j = nbr[i, k]
            touching, n0, n1, n2, delta = pair_normal(pos, radius, i, j, length, periodic)
            if not touching:
                continue
            rj = radius[j]
            row = table[0, 0] if single else table[ci, material[j]]
            u0, u1, u2 = pair_slip(vel_pred, angvel_pred, i, j, ri, rj, n0, n1, n2)
            un = u0 * n0 + u1 * n1 + u2 * n2
            root_m = math.sqrt(reduced(inv_mass[i], inv_mass[j]))
            r_eff = ri * rj / (ri + rj)
            fn, kt, ct = normal_law(
                row[K_N], row[K_T], row[D_N], row[D_T], law, delta, r_eff, root_m, un, 0.0, 1.0
            )
            for a in range(3):  # (no springs without friction)
                scratch[i, 0, a] = hist[start[i] + k, a] if hist.shape[0] > 0 else 0.0
            g0, g1, g2 = tangential_force(
                scratch, i, 0, 0.0, 0.0, 0.0, n0, n1, n2, kt, ct, row[MU], fn, 0.0,
                u0 - un * n0, u1 - un * n1, u2 - un * n2, 1.0,
            )  # fmt: skip
            _add_moment(moment, i, ri, n0, n1, n2, fn * n0 + g0, fn * n1 + g1, fn * n2 + g2)
            # on j: the opposite force at x_j + r_j n, i.e. (-r_j)(-n) (x) (-f)
            _add_moment(moment, j, rj, n0, n1, n2, fn * n0 + g0, fn * n1 + g1, fn * n2 + g2)
        for w in range(wall_axis.shape[0]):
            if inv_mass[i] == 0.0:
                break  # walls neither touch nor push particles moved by prescription
            touching, n0, n1, n2, delta = wall_normal(pos, radius, i, w, wall_axis, wall_sign, wall_coord)
            if not touching:
                continue
            row = wall_table[w, 0] if wall_single else wall_table[w, material[i]]
            u0, u1, u2 = wall_slip(
                vel_pred, angvel_pred, i, ri, n0, n1, n2, wall_vel[w, 0], wall_vel[w, 1], wall_vel[w, 2]
            )
            un = u0 * n0 + u1 * n1 + u2 * n2
            fn, kt, ct = normal_law(
                row[K_N], row[K_T], row[D_N], row[D_T], law, delta, ri, math.sqrt(mi), un, 0.0, 1.0
            )
            for a in range(3):
                scratch[i, 0, a] = wall_hist[i, w, a] if wall_hist.shape[0] > 0 else 0.0
            g0, g1, g2 = tangential_force(
                scratch, i, 0, 0.0, 0.0, 0.0, n0, n1, n2, kt, ct, row[MU], fn, 0.0,
                u0 - un * n0, u1 - un * n1, u2 - un * n2, 1.0,
            )  # fmt: skip
            _add_moment(moment, i, ri, n0, n1, n2, fn * n0 + g0, fn * n1 + g1, fn * n2 + g2)


@njit(cache=True)
def layer_sums(pos, vel, mass, moment, z0, dz, layers, count, momentum, mass_sum, virial, kinetic):
    """Per horizontal layer l (particles with z0 + l dz <= z < z0 + (l+1) dz, clipped into the
    first and last layer): count (L,), momentum (L,3) [kg m/s], mass_sum (L,) [kg], virial (L,3,3)
    = sum of moments [N m], kinetic (L,3,3) = sum of m v' (x) v' about the layer's mean velocity
    [J]. Serial, in particle order (thread-count independent)."""
    count[:] = 0
    momentum[:] = 0.0
    mass_sum[:] = 0.0
    virial[:] = 0.0
    kinetic[:] = 0.0
    n = pos.shape[0]
    for i in range(n):
        l = _layer(pos[i, 2], z0, dz, layers)
        count[l] += 1
        mass_sum[l] += mass[i]
        for a in range(3):
            momentum[l, a] += mass[i] * vel[i, a]
            for b in range(3):
                virial[l, a, b] += moment[i, a, b]
    for i in range(n):
        l = _layer(pos[i, 2], z0, dz, layers)
        m = mass_sum[l]
        for a in range(3):
            va = vel[i, a] - momentum[l, a] / m
            for b in range(3):
                vb = vel[i, b] - momentum[l, b] / m
                kinetic[l, a, b] += mass[i] * va * vb


@njit(cache=True, inline="always")
def _layer(z, z0, dz, layers):
    l = int(math.floor((z - z0) / dz))
    if l < 0:
        return 0
    if l >= layers:
        return layers - 1
    return l
