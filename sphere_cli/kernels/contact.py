"""Linear spring-dashpot contacts with an elastic tangential spring and a Coulomb cap.

Normal force on i from j (Cundall & Strack 1979; shared/validation A1):
    F_n = max(0, k_n delta - c_n v_n),  c_n = 2 zeta sqrt(k_n m*),  m* = m_i m_j/(m_i + m_j)
never attractive; zeta is calibrated so the realised restitution is the requested one.
Tangential: a spring xi, rotated into the current contact plane, grown by the tangential
slip velocity each step; F_t = -k_t xi - c_t v_t (c_t = 2 zeta sqrt(k_t m*)), capped at mu F_n,
where xi is reset to the spring length consistent with the capped force (Luding 2008).

Gather form: a prange over particles, each summing over its own neighbour row and writing only
its own force, torque and history row. Every operation is antisymmetric in (i, j), so the
two copies of a pair's history stay exact negatives and the forces are equal and opposite to
the last bit.

Arguments: pos, vel, angvel (N,3) [m, m/s, rad/s]; radius, mass (N,) [m, kg];
nbr (N,C) int32, nbr_count (N,); hist (N,C,3) [m]; body_acc (3,) [m/s^2] (gravity);
length (3,) [m], periodic (3,) uint8; out force, torque (N,3) [N, N m].
"""

import math

from numba import njit, prange

from .neighbors import minimum_image


@njit(cache=True, inline="always")
def tangential_force(hist, i, k, vt0, vt1, vt2, n0, n1, n2, kt, ct, mu, fn, dt, ut0, ut1, ut2):
    """Update the spring xi = hist[i, k] (3,) in place and return F_t as a tuple [N].

    vt: tangential slip velocity at the half step (grows the spring: exact midpoint rule);
    ut: the same at the predicted full step (the dashpot acts at the time of the force)."""
    x0 = hist[i, k, 0]
    x1 = hist[i, k, 1]
    x2 = hist[i, k, 2]
    # rotate the spring into the current tangent plane, keeping its length
    old2 = x0 * x0 + x1 * x1 + x2 * x2
    if old2 > 0.0:
        dot = x0 * n0 + x1 * n1 + x2 * n2
        x0 -= dot * n0
        x1 -= dot * n1
        x2 -= dot * n2
        new2 = x0 * x0 + x1 * x1 + x2 * x2
        if new2 > 0.0 and new2 != old2:
            scale = math.sqrt(old2 / new2)
            x0 *= scale
            x1 *= scale
            x2 *= scale
    x0 += vt0 * dt
    x1 += vt1 * dt
    x2 += vt2 * dt
    f0 = -kt * x0 - ct * ut0
    f1 = -kt * x1 - ct * ut1
    f2 = -kt * x2 - ct * ut2
    ft2 = f0 * f0 + f1 * f1 + f2 * f2
    cap = mu * fn
    if ft2 > cap * cap:
        ratio = cap / math.sqrt(ft2)
        f0 *= ratio
        f1 *= ratio
        f2 *= ratio
        x0 = -(f0 + ct * ut0) / kt
        x1 = -(f1 + ct * ut1) / kt
        x2 = -(f2 + ct * ut2) / kt
    hist[i, k, 0] = x0
    hist[i, k, 1] = x1
    hist[i, k, 2] = x2
    return f0, f1, f2


@njit(cache=True, parallel=True)
def linear_pair_forces(
    pos,
    vel,
    angvel,
    vel_pred,
    angvel_pred,
    radius,
    mass,
    nbr,
    nbr_count,
    hist,
    kn,
    kt,
    zeta,
    mu,
    body_acc,
    length,
    periodic,
    dt,
    force,
    torque,
):
    """Set force = m g + sum of pair forces and torque = sum of pair torques, per particle."""
    n = pos.shape[0]
    cap = nbr.shape[1]
    damp_n = 2.0 * zeta * math.sqrt(kn)  # c_n = damp_n sqrt(m*)
    damp_t = 2.0 * zeta * math.sqrt(kt)
    for i in prange(n):
        ri = radius[i]
        mi = mass[i]
        f0 = mi * body_acc[0]
        f1 = mi * body_acc[1]
        f2 = mi * body_acc[2]
        t0 = 0.0
        t1 = 0.0
        t2 = 0.0
        count = min(nbr_count[i], cap)
        for k in range(count):
            j = nbr[i, k]
            d0 = minimum_image(pos[i, 0] - pos[j, 0], length[0], periodic[0])
            d1 = minimum_image(pos[i, 1] - pos[j, 1], length[1], periodic[1])
            d2 = minimum_image(pos[i, 2] - pos[j, 2], length[2], periodic[2])
            dist2 = d0 * d0 + d1 * d1 + d2 * d2
            rj = radius[j]
            reach = ri + rj
            if dist2 >= reach * reach:
                if hist[i, k, 0] != 0.0 or hist[i, k, 1] != 0.0 or hist[i, k, 2] != 0.0:
                    hist[i, k, 0] = 0.0  # the pair has separated: its spring is gone
                    hist[i, k, 1] = 0.0
                    hist[i, k, 2] = 0.0
                continue
            dist = math.sqrt(dist2)
            inv = 1.0 / dist
            n0 = d0 * inv
            n1 = d1 * inv
            n2 = d2 * inv
            delta = reach - dist
            # contact-point velocity of i relative to j: v_i - v_j - (r_i w_i + r_j w_j) x n
            s0 = ri * angvel[i, 0] + rj * angvel[j, 0]
            s1 = ri * angvel[i, 1] + rj * angvel[j, 1]
            s2 = ri * angvel[i, 2] + rj * angvel[j, 2]
            v0 = (vel[i, 0] - vel[j, 0]) - (s1 * n2 - s2 * n1)
            v1 = (vel[i, 1] - vel[j, 1]) - (s2 * n0 - s0 * n2)
            v2 = (vel[i, 2] - vel[j, 2]) - (s0 * n1 - s1 * n0)
            vn = v0 * n0 + v1 * n1 + v2 * n2
            # the same at the predicted full step, for the dashpots
            q0 = ri * angvel_pred[i, 0] + rj * angvel_pred[j, 0]
            q1 = ri * angvel_pred[i, 1] + rj * angvel_pred[j, 1]
            q2 = ri * angvel_pred[i, 2] + rj * angvel_pred[j, 2]
            u0 = (vel_pred[i, 0] - vel_pred[j, 0]) - (q1 * n2 - q2 * n1)
            u1 = (vel_pred[i, 1] - vel_pred[j, 1]) - (q2 * n0 - q0 * n2)
            u2 = (vel_pred[i, 2] - vel_pred[j, 2]) - (q0 * n1 - q1 * n0)
            un = u0 * n0 + u1 * n1 + u2 * n2
            mj = mass[j]
            root_m = math.sqrt(mi * mj / (mi + mj))  # sqrt of the reduced mass
            fn = kn * delta - damp_n * root_m * un
            if fn < 0.0:
                fn = 0.0
            vt0 = v0 - vn * n0
            vt1 = v1 - vn * n1
            vt2 = v2 - vn * n2
            ct = damp_t * root_m
            g0, g1, g2 = tangential_force(
                hist,
                i,
                k,
                vt0,
                vt1,
                vt2,
                n0,
                n1,
                n2,
                kt,
                ct,
                mu,
                fn,
                dt,
                u0 - un * n0,
                u1 - un * n1,
                u2 - un * n2,
            )
            f0 += fn * n0 + g0
            f1 += fn * n1 + g1
            f2 += fn * n2 + g2
            # torque of F_t applied at the contact point x_i - r_i n
            t0 -= ri * (n1 * g2 - n2 * g1)
            t1 -= ri * (n2 * g0 - n0 * g2)
            t2 -= ri * (n0 * g1 - n1 * g0)
        force[i, 0] = f0
        force[i, 1] = f1
        force[i, 2] = f2
        torque[i, 0] = t0
        torque[i, 1] = t1
        torque[i, 2] = t2
