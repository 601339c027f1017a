"""Particle-particle contacts: linear or Hertz-Mindlin normal law, tangential spring with a Coulomb
cap, optional constant-torque rolling resistance; per-pair parameters from an (M, M, 6) table.

Normal force on i from j, overlap delta, reduced mass m* = m_i m_j/(m_i + m_j), normal approach
speed v_n (predicted full-step velocity), clamped so it is never attractive:
  linear (Cundall & Strack 1979):  F_n = max(0, k_n delta - c_n v_n),  c_n = 2 zeta sqrt(k_n m*);
  Hertz with the Tsuji dashpot (Tsuji, Tanaka & Ishida 1992, Powder Technol. 71:239):
      F_n = max(0, (4/3) E* sqrt(R*) delta^{3/2} - c_h sqrt(m* k_h) delta^{1/4} v_n),
      k_h = (4/3) E* sqrt(R*),  1/R* = 1/r_i + 1/r_j.
zeta and c_h are calibrated (physics/restitution.py) so that the clamped contact rebounds at the
requested restitution e exactly (for the Hertz law at every impact speed).
Both laws are written with s = 1 (linear) or s = sqrt(R* delta) (Hertz), so one code serves both:
  F_n = max(0, K_N s delta - D_N sqrt(s) sqrt(m*) v_n),  k_t = K_T s,  c_t = D_T sqrt(s) sqrt(m*),
with the table columns K_N = k_n | (4/3) E*, K_T = k_t | 8 G* (Mindlin no-slip stiffness
k_t = 8 G* sqrt(R* delta), Mindlin 1949), D_N = 2 zeta sqrt(k_n) | c_h sqrt(4 E*/3),
D_T = 2 zeta sqrt(k_t) | c_h sqrt(16 G*/3). The tangential dashpot has the damping ratio of the
normal one relative to its own stiffness (c_t/c_n = sqrt(k_t/(dF_n/d delta)) for both laws).
Tangential: a spring xi, rotated into the current contact plane, grown by the slip velocity at
the half step; F_t = -k_t xi - c_t u_t (u_t: slip at the predicted full step), capped at mu F_n.
While sliding, xi is reset so that the spring alone carries the capped force, xi = -F_t/k_t (the
dashpot damps sticking contacts only). Resetting it to -(F_t + c_t u_t)/k_t (Luding 2008) would
store the dashpot force in the spring; with the Mindlin k_t ~ delta^{1/2} growing faster than
c_t ~ delta^{1/4} that stored force then reverses the friction early in a sliding Hertz impact.
Rolling resistance, model type A of Ai, Chen, Rotter & Ooi (2011, Powder Technol. 206:269):
a torque M = -mu_r R* F_n w/|w| on i, w the rolling part (tangent to the contact plane) of the
relative angular velocity w_i - w_j at the half step, limited to I* |w|/dt (1/I* = 1/I_i + 1/I_j)
so that it stops, and never reverses, the relative rolling within one step. The limit is per
contact: a sphere braked by several contacts at once can overshoot, leaving a jitter of its spin
at rest bounded by one step's rolling impulse (sum of mu_r R* F_n) dt/I.

Half list, particles owned by chunks (design guide 3). Each listed pair (i, j > i) is computed
once. The particles are cut into contiguous index chunks, one per thread; a chunk owns the
forces of its particles and sweeps its rows in ascending i. A pair whose partner j lies in the
same chunk is applied at once to both members (force on j: the negative, torque on j with r_j),
which no other thread touches; a pair whose j lies in a later chunk is computed beforehand into
its own slot (cross_chunk_pairs) and read back by both owners. Each particle's sum is then always
m g, minus its pairs (j, i) with j < i in ascending j, plus its own row in ascending j, whatever
the number of chunks: the result is bitwise the same for any thread count (one thread: one
chunk, no slots at all). Every operation is antisymmetric in (i, j), so the force on j is exactly
the negative of the force on i.

Arguments: pos, vel, angvel, vel_pred, angvel_pred (N,3) [m, m/s, rad/s]; radius, mass, inertia
(N,) [m, kg, kg m^2]; material (N,) int32 index into the table; nbr (N,C) int32 half rows,
nbr_count (N,); rev (N,R) int32 reverse slots, rev_count (N,) (kernels/neighbors.py);
bounds (T+1,) int64 chunk boundaries (chunk c: bounds[c] <= i < bounds[c+1]);
hist (N,C,3) [m]; table (M,M,6) per pair of materials, columns K_N, K_T, D_N, D_T, MU, MU_R as
above [N/m or Pa, N/m or Pa, kg^1/2/s or (Pa kg)^1/2 m^-1/2, same, -, -]; hertz, rolling flags;
body_acc (3,) [m/s^2] (gravity); length (3,) [m], periodic (3,) uint8; spring_dt [s] (the
tangential spring's growth, 0 for the forces of the initial state), step_dt [s] (the rolling
limit); slots (N*C, 6 or 9 with rolling) [N, N, N m], pair (i, nbr[i, k]) at i*C + k, used
for the pairs across chunks only; out force, torque (N,3) [N, N m].
"""

import math

import numpy as np
from numba import njit, prange

from .neighbors import minimum_image

# columns of the per-pair parameter table
K_N = 0
K_T = 1
D_N = 2
D_T = 3
MU = 4
MU_R = 5
COLUMNS = 6


@njit(cache=True, inline="always")
def normal_law(kn, kt, dn, dt, hertz, delta, r_eff, root_m, un):
    """(F_n clamped at 0 [N], k_t [N/m], c_t [kg/s]) of one contact; kn, kt, dn, dt: the columns
    K_N, K_T, D_N, D_T of its table row."""
    if hertz:
        s = math.sqrt(r_eff * delta)
        root_s = math.sqrt(s)
        fn = kn * s * delta - dn * root_s * root_m * un
        kt = kt * s
        ct = dt * root_s * root_m
    else:
        fn = kn * delta - dn * root_m * un
        ct = dt * root_m
    if fn < 0.0:
        fn = 0.0
    return fn, kt, ct


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
        x0 = -f0 / kt
        x1 = -f1 / kt
        x2 = -f2 / kt
    hist[i, k, 0] = x0
    hist[i, k, 1] = x1
    hist[i, k, 2] = x2
    return f0, f1, f2


@njit(cache=True, inline="always")
def rolling_torque(w0, w1, w2, n0, n1, n2, mu_r, r_eff, fn, i_eff, dt):
    """Constant rolling-resistance torque [N m] on a body whose angular velocity relative to the
    other is w (3,) [rad/s]: -min(mu_r R* F_n, I* |w_r|/dt) w_r/|w_r|, w_r = w - (w.n) n."""
    dot = w0 * n0 + w1 * n1 + w2 * n2
    r0 = w0 - dot * n0
    r1 = w1 - dot * n1
    r2 = w2 - dot * n2
    size = math.sqrt(r0 * r0 + r1 * r1 + r2 * r2)
    if size == 0.0:
        return 0.0, 0.0, 0.0
    torque = mu_r * r_eff * fn
    stop = i_eff * size / dt
    if torque > stop:
        torque = stop
    scale = -torque / size
    return scale * r0, scale * r1, scale * r2


@njit(cache=True, inline="always")
def pair_force(
    i,
    k,
    j,
    own,
    pos,
    vel,
    angvel,
    vel_pred,
    angvel_pred,
    radius,
    mass,
    inertia,
    params,
    hist,
    hertz,
    rolling,
    length,
    periodic,
    spring_dt,
    step_dt,
):
    """Contact of pair (i, j = nbr[i, k]); own: i's (x0, x1, x2, v0, v1, v2, r w0, r w1, r w2,
    vp0, vp1, vp2, r wp0, r wp1, r wp2, r, m) (velocities at the half step and predicted).
    Updates the spring hist[i, k] (cleared when the pair does not touch) and returns
    (touching, force on i (3), n x F_t (3), rolling torque on i (3)); the torque of F_t on i is
    -r_i n x F_t, on j -r_j n x F_t; on j the force and rolling torque are the negatives."""
    ri = own[15]
    d0 = minimum_image(own[0] - pos[j, 0], length[0], periodic[0])
    d1 = minimum_image(own[1] - pos[j, 1], length[1], periodic[1])
    d2 = minimum_image(own[2] - pos[j, 2], length[2], periodic[2])
    dist2 = d0 * d0 + d1 * d1 + d2 * d2
    rj = radius[j]
    reach = ri + rj
    if dist2 >= reach * reach:
        if hist[i, k, 0] != 0.0 or hist[i, k, 1] != 0.0 or hist[i, k, 2] != 0.0:
            hist[i, k, 0] = 0.0  # the pair has separated: its spring is gone
            hist[i, k, 1] = 0.0
            hist[i, k, 2] = 0.0
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    kn, kt, dn, dt, mu, mu_r = params
    dist = math.sqrt(dist2)
    inv = 1.0 / dist
    n0 = d0 * inv
    n1 = d1 * inv
    n2 = d2 * inv
    delta = reach - dist
    # contact-point velocity of i relative to j: v_i - v_j - (r_i w_i + r_j w_j) x n
    s0 = own[6] + rj * angvel[j, 0]
    s1 = own[7] + rj * angvel[j, 1]
    s2 = own[8] + rj * angvel[j, 2]
    v0 = (own[3] - vel[j, 0]) - (s1 * n2 - s2 * n1)
    v1 = (own[4] - vel[j, 1]) - (s2 * n0 - s0 * n2)
    v2 = (own[5] - vel[j, 2]) - (s0 * n1 - s1 * n0)
    vn = v0 * n0 + v1 * n1 + v2 * n2
    # the same at the predicted full step, for the dashpots
    q0 = own[12] + rj * angvel_pred[j, 0]
    q1 = own[13] + rj * angvel_pred[j, 1]
    q2 = own[14] + rj * angvel_pred[j, 2]
    u0 = (own[9] - vel_pred[j, 0]) - (q1 * n2 - q2 * n1)
    u1 = (own[10] - vel_pred[j, 1]) - (q2 * n0 - q0 * n2)
    u2 = (own[11] - vel_pred[j, 2]) - (q0 * n1 - q1 * n0)
    un = u0 * n0 + u1 * n1 + u2 * n2
    mi = own[16]
    mj = mass[j]
    root_m = math.sqrt(mi * mj / (mi + mj))  # sqrt of the reduced mass
    r_eff = 0.0
    if hertz or rolling:
        r_eff = ri * rj / (ri + rj)
    fn, kt_now, ct = normal_law(kn, kt, dn, dt, hertz, delta, r_eff, root_m, un)
    g0, g1, g2 = tangential_force(
        hist,
        i,
        k,
        v0 - vn * n0,
        v1 - vn * n1,
        v2 - vn * n2,
        n0,
        n1,
        n2,
        kt_now,
        ct,
        mu,
        fn,
        spring_dt,
        u0 - un * n0,
        u1 - un * n1,
        u2 - un * n2,
    )
    m0 = 0.0
    m1 = 0.0
    m2 = 0.0
    if rolling and mu_r > 0.0:
        ii = inertia[i]
        ij = inertia[j]
        m0, m1, m2 = rolling_torque(
            angvel[i, 0] - angvel[j, 0],
            angvel[i, 1] - angvel[j, 1],
            angvel[i, 2] - angvel[j, 2],
            n0,
            n1,
            n2,
            mu_r,
            r_eff,
            fn,
            ii * ij / (ii + ij),
            step_dt,
        )
    # F_t acts at the contact point x_i - r_i n (on j: x_j + r_j n, with -F_t)
    return (
        True,
        fn * n0 + g0,
        fn * n1 + g1,
        fn * n2 + g2,
        n1 * g2 - n2 * g1,
        n2 * g0 - n0 * g2,
        n0 * g1 - n1 * g0,
        m0,
        m1,
        m2,
    )


@njit(cache=True, inline="always")
def own_state(i, pos, vel, angvel, vel_pred, angvel_pred, radius, mass):
    """The tuple `own` of pair_force for particle i."""
    ri = radius[i]
    return (
        pos[i, 0],
        pos[i, 1],
        pos[i, 2],
        vel[i, 0],
        vel[i, 1],
        vel[i, 2],
        ri * angvel[i, 0],
        ri * angvel[i, 1],
        ri * angvel[i, 2],
        vel_pred[i, 0],
        vel_pred[i, 1],
        vel_pred[i, 2],
        ri * angvel_pred[i, 0],
        ri * angvel_pred[i, 1],
        ri * angvel_pred[i, 2],
        ri,
        mass[i],
    )


@njit(cache=True, inline="always")
def pair_params(table, material, single, i, j):
    """(K_N, K_T, D_N, D_T, MU, MU_R) of the pair's materials."""
    a = np.uint64(0 if single else material[i])
    b = np.uint64(0 if single else material[j])
    return (
        table[a, b, K_N],
        table[a, b, K_T],
        table[a, b, D_N],
        table[a, b, D_T],
        table[a, b, MU],
        table[a, b, MU_R],
    )


@njit(cache=True, inline="always")
def cross_start(nbr, i, count, end):
    """First k of row i whose partner lies at or beyond index `end` (the row is ascending, so
    those partners are a suffix)."""
    first = count
    while first > 0 and nbr[i, first - 1] >= end:
        first -= 1
    return first


# Index arithmetic below is unsigned (np.uint64): a signed index makes Numba emit a
# negative-index wraparound for every array access, which costs ~10 % in these loops. Never
# compare or mix an unsigned value with a signed one (Numba would convert both to float).


@njit(cache=True, parallel=True)
def cross_chunk_pairs(
    pos,
    vel,
    angvel,
    vel_pred,
    angvel_pred,
    radius,
    mass,
    inertia,
    material,
    nbr,
    nbr_count,
    hist,
    table,
    hertz,
    rolling,
    length,
    periodic,
    spring_dt,
    step_dt,
    bounds,
    slots,
):
    """Every listed pair whose partner lies in a later chunk, into its slot s = i*C + k:
    slots[s, 0:3] the force on i, [3:6] n x F_t, [6:9] the rolling torque on i (with rolling);
    zero for a pair that does not touch."""
    cap = nbr.shape[1]
    ucap = np.uint64(cap)
    single = table.shape[0] == 1
    for c in prange(bounds.shape[0] - 1):
        end = bounds[c + 1]
        for row in range(bounds[c], end):
            i = np.uint64(row)
            count = min(nbr_count[i], cap)
            first = cross_start(nbr, i, count, end)
            if first == count:
                continue  # most rows: no partner beyond the chunk
            own = own_state(i, pos, vel, angvel, vel_pred, angvel_pred, radius, mass)
            for slot in range(first, count):
                k = np.uint64(slot)
                j = np.uint64(nbr[i, k])
                params = pair_params(table, material, single, i, j)
                touching, e0, e1, e2, c0, c1, c2, m0, m1, m2 = pair_force(
                    i,
                    k,
                    j,
                    own,
                    pos,
                    vel,
                    angvel,
                    vel_pred,
                    angvel_pred,
                    radius,
                    mass,
                    inertia,
                    params,
                    hist,
                    hertz,
                    rolling,
                    length,
                    periodic,
                    spring_dt,
                    step_dt,
                )
                s = i * ucap + k
                slots[s, 0] = e0
                slots[s, 1] = e1
                slots[s, 2] = e2
                slots[s, 3] = c0
                slots[s, 4] = c1
                slots[s, 5] = c2
                if rolling:
                    slots[s, 6] = m0
                    slots[s, 7] = m1
                    slots[s, 8] = m2


@njit(cache=True, parallel=True)
def chunk_pair_forces(
    pos,
    vel,
    angvel,
    vel_pred,
    angvel_pred,
    radius,
    mass,
    inertia,
    material,
    nbr,
    nbr_count,
    hist,
    table,
    hertz,
    rolling,
    length,
    periodic,
    spring_dt,
    step_dt,
    rev,
    rev_count,
    body_acc,
    bounds,
    slots,
    force,
    torque,
):
    """Set force = m g + the sum of the pair forces and torque = the sum of the pair torques,
    chunk by chunk: first m g minus the pairs (j, i) with j in an earlier chunk (their slots,
    ascending j), then a sweep in ascending i applying the pairs inside the chunk to both
    members and adding the row's pairs beyond the chunk from their slots (cross_chunk_pairs
    must have run). Each particle's terms come in ascending partner index (module docstring)."""
    cap = nbr.shape[1]
    ucap = np.uint64(cap)
    rcap = rev.shape[1]
    single = table.shape[0] == 1
    for c in prange(bounds.shape[0] - 1):
        begin = bounds[c]
        end = bounds[c + 1]
        for row in range(begin, end):
            i = np.uint64(row)
            ri = radius[i]
            mi = mass[i]
            f0 = mi * body_acc[0]
            f1 = mi * body_acc[1]
            f2 = mi * body_acc[2]
            t0 = 0.0
            t1 = 0.0
            t2 = 0.0
            # the reverse row is ascending in j: pairs from earlier chunks are a prefix (none
            # for the first chunk, which then reads no reverse row)
            for m in range(min(rev_count[i], rcap) if begin > 0 else 0):
                if rev[i, m] >= begin * cap:
                    break
                s = np.uint64(rev[i, m])
                f0 -= slots[s, 0]
                f1 -= slots[s, 1]
                f2 -= slots[s, 2]
                t0 -= ri * slots[s, 3]
                t1 -= ri * slots[s, 4]
                t2 -= ri * slots[s, 5]
                if rolling:
                    t0 -= slots[s, 6]
                    t1 -= slots[s, 7]
                    t2 -= slots[s, 8]
            force[i, 0] = f0
            force[i, 1] = f1
            force[i, 2] = f2
            torque[i, 0] = t0
            torque[i, 1] = t1
            torque[i, 2] = t2
        for row in range(begin, end):
            i = np.uint64(row)
            ri = radius[i]
            own = own_state(i, pos, vel, angvel, vel_pred, angvel_pred, radius, mass)
            # every pair (j, i), j < i, is in force[i] by now
            f0 = force[i, 0]
            f1 = force[i, 1]
            f2 = force[i, 2]
            t0 = torque[i, 0]
            t1 = torque[i, 1]
            t2 = torque[i, 2]
            count = min(nbr_count[i], cap)
            inner = cross_start(nbr, i, count, end)
            for slot in range(inner):
                k = np.uint64(slot)
                j = np.uint64(nbr[i, k])
                params = pair_params(table, material, single, i, j)
                touching, e0, e1, e2, c0, c1, c2, m0, m1, m2 = pair_force(
                    i,
                    k,
                    j,
                    own,
                    pos,
                    vel,
                    angvel,
                    vel_pred,
                    angvel_pred,
                    radius,
                    mass,
                    inertia,
                    params,
                    hist,
                    hertz,
                    rolling,
                    length,
                    periodic,
                    spring_dt,
                    step_dt,
                )
                if not touching:
                    continue
                f0 += e0
                f1 += e1
                f2 += e2
                t0 -= ri * c0
                t1 -= ri * c1
                t2 -= ri * c2
                rj = radius[j]
                force[j, 0] -= e0
                force[j, 1] -= e1
                force[j, 2] -= e2
                torque[j, 0] -= rj * c0
                torque[j, 1] -= rj * c1
                torque[j, 2] -= rj * c2
                if rolling:
                    t0 += m0
                    t1 += m1
                    t2 += m2
                    torque[j, 0] -= m0
                    torque[j, 1] -= m1
                    torque[j, 2] -= m2
            for slot in range(inner, count):
                s = i * ucap + np.uint64(slot)
                f0 += slots[s, 0]
                f1 += slots[s, 1]
                f2 += slots[s, 2]
                t0 -= ri * slots[s, 3]
                t1 -= ri * slots[s, 4]
                t2 -= ri * slots[s, 5]
                if rolling:
                    t0 += slots[s, 6]
                    t1 += slots[s, 7]
                    t2 += slots[s, 8]
            force[i, 0] = f0
            force[i, 1] = f1
            force[i, 2] = f2
            torque[i, 0] = t0
            torque[i, 1] = t1
            torque[i, 2] = t2
