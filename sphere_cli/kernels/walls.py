"""Plane walls on the faces of the box: the contact law of `contact.py` (linear or Hertz-Mindlin,
tangential spring with Coulomb cap, optional rolling resistance) against a fixed body of
infinite mass and radius: m* = m_i, R* = r_i, I* = I_i, relative spin w_i.

Arguments: pos, vel, angvel, vel_pred, angvel_pred (N,3); radius, mass, inertia (N,); material
(N,) int32; wall_axis (W,) int64 axis of the normal; wall_sign (W,) +1.0 on a lower face (normal
along +axis), -1.0 on an upper face; wall_coord (W,) [m]; wall_table (W,M,6) parameters of wall w
against material m, columns as in contact.py (the wall's own elasticity, if any, is in E* and
G*; a rigid wall has none); wall_hist (N,W,3) [m]; force, torque (N,3) accumulated in place.
"""

import math

from numba import njit, prange

from .contact import D_N, D_T, K_N, K_T, MU, MU_R, normal_law, rolling_torque, tangential_force


@njit(cache=True, parallel=True)
def wall_forces(
    pos,
    vel,
    angvel,
    vel_pred,
    angvel_pred,
    radius,
    mass,
    inertia,
    material,
    wall_axis,
    wall_sign,
    wall_coord,
    wall_table,
    wall_hist,
    hertz,
    rolling,
    spring_dt,
    step_dt,
    force,
    torque,
):
    """Add the forces and torques of W plane walls to force/torque."""
    n = pos.shape[0]
    nw = wall_axis.shape[0]
    single = wall_table.shape[1] == 1
    for i in prange(n):
        ri = radius[i]
        root_m = math.sqrt(mass[i])
        ci = 0 if single else material[i]
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        t0 = 0.0
        t1 = 0.0
        t2 = 0.0
        for w in range(nw):
            a = wall_axis[w]
            gap = wall_sign[w] * (pos[i, a] - wall_coord[w])
            if gap >= ri:
                wall_hist[i, w, 0] = 0.0
                wall_hist[i, w, 1] = 0.0
                wall_hist[i, w, 2] = 0.0
                continue
            row = wall_table[w, ci]
            n0 = 0.0
            n1 = 0.0
            n2 = 0.0
            if a == 0:
                n0 = wall_sign[w]
            elif a == 1:
                n1 = wall_sign[w]
            else:
                n2 = wall_sign[w]
            delta = ri - gap
            s0 = ri * angvel[i, 0]
            s1 = ri * angvel[i, 1]
            s2 = ri * angvel[i, 2]
            v0 = vel[i, 0] - (s1 * n2 - s2 * n1)
            v1 = vel[i, 1] - (s2 * n0 - s0 * n2)
            v2 = vel[i, 2] - (s0 * n1 - s1 * n0)
            vn = v0 * n0 + v1 * n1 + v2 * n2
            q0 = ri * angvel_pred[i, 0]
            q1 = ri * angvel_pred[i, 1]
            q2 = ri * angvel_pred[i, 2]
            u0 = vel_pred[i, 0] - (q1 * n2 - q2 * n1)
            u1 = vel_pred[i, 1] - (q2 * n0 - q0 * n2)
            u2 = vel_pred[i, 2] - (q0 * n1 - q1 * n0)
            un = u0 * n0 + u1 * n1 + u2 * n2
            fn, kt, ct = normal_law(row[K_N], row[K_T], row[D_N], row[D_T], hertz, delta, ri, root_m, un)
            vt0 = v0 - vn * n0
            vt1 = v1 - vn * n1
            vt2 = v2 - vn * n2
            g0, g1, g2 = tangential_force(
                wall_hist,
                i,
                w,
                vt0,
                vt1,
                vt2,
                n0,
                n1,
                n2,
                kt,
                ct,
                row[MU],
                fn,
                spring_dt,
                u0 - un * n0,
                u1 - un * n1,
                u2 - un * n2,
            )
            f0 += fn * n0 + g0
            f1 += fn * n1 + g1
            f2 += fn * n2 + g2
            t0 -= ri * (n1 * g2 - n2 * g1)
            t1 -= ri * (n2 * g0 - n0 * g2)
            t2 -= ri * (n0 * g1 - n1 * g0)
            if rolling and row[MU_R] > 0.0:
                m0, m1, m2 = rolling_torque(
                    angvel[i, 0],
                    angvel[i, 1],
                    angvel[i, 2],
                    n0,
                    n1,
                    n2,
                    row[MU_R],
                    ri,
                    fn,
                    inertia[i],
                    step_dt,
                )
                t0 += m0
                t1 += m1
                t2 += m2
        force[i, 0] += f0
        force[i, 1] += f1
        force[i, 2] += f2
        torque[i, 0] += t0
        torque[i, 1] += t1
        torque[i, 2] += t2
