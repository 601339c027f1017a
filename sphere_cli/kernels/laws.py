"""Particle-particle contacts: linear or Hertz-Mindlin normal law, tangential spring with a Coulomb
cap, optional constant-torque rolling resistance; per-pair parameters from an (M, M, 6) table.

Normal force on i from j, overlap delta, reduced mass m* = 1/(1/m_i + 1/m_j) (m_i where j is
prescribed, `reduced`), normal approach
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

Law codes: the kernels take the law as an integer (LINEAR, HERTZ_MINDLIN), the physics side as
an object (physics/laws/); a new law adds its code and its branch in normal_law here and in the
elastic energy (kernels/observe/energy.py).
"""

import math

from numba import njit

# columns of the per-pair parameter table
K_N = 0
K_T = 1
D_N = 2
D_T = 3
MU = 4
MU_R = 5
COLUMNS = 6

# the contact laws, as the kernels know them (physics/laws/ holds each law's parameters)
LINEAR = 0
HERTZ_MINDLIN = 1


@njit(cache=True, inline="always")
def contact_window(delta, vn, un, step):
    """(travel [m], grow, end) of a contact of overlap delta [m] whose surfaces moved apart at
    vn over the last half step and move at un at the predicted full step [m/s] (v.n, positive
    apart), for velocity Verlet, which applies each force for one step around its instant,
    across the touch and the parting, which fall anywhere inside a step:
    - the first step of a contact (the overlap before, delta + vn step, was <= 0): travel =
      -vn step, and the spring grows by the fraction grow = delta/travel of the step's slip
      that the contact has lasted;
    - the last one (the overlap next, delta - un step, will be <= 0; un estimates the speed
      between now and the parting, to first order, which makes the estimate second order):
      travel = un step, and the tangential force, which unlike the normal one does not vanish
      at the parting, is weighted by end = (delta/un + step/2)/step, the time it acts within the
      step's window [t - step/2, parting];
    elsewhere (0, 1, 1). normal_law takes the normal force's part."""
    closing = -vn * step
    if closing > delta:
        return closing, delta / closing, 1.0
    opening = un * step
    if opening > delta:
        return opening, 1.0, (delta + 0.5 * opening) / opening
    return 0.0, 1.0, 1.0


@njit(cache=True, inline="always")
def normal_law(kn, kt, dn, dt, law, delta, r_eff, root_m, un, travel, grow):
    """(F_n clamped at 0 [N], k_t [N/m], c_t [kg/s]) of one contact; kn, kt, dn, dt: the columns
    K_N, K_T, D_N, D_T of its table row; un: the normal velocity the dashpot acts on [m/s].

    travel, grow: those of contact_window; with travel = 0 this is the law at the instant.
    Otherwise the surfaces touched within the last step (grow < 1) or part within the next,
    and F_n is the mean force over the step's window [t - dt/2, t + dt/2] instead, so that the
    steps give the impulse of the continuous contact: the overlap moves linearly between the
    touch (or parting) and the window's far edge, where it is x = delta + travel/2, so the
    elastic impulse is W(x)/speed, W the elastic energy (k x^2/2; Hertz (2/5) K_N sqrt(R*)
    x^5/2), and a dashpot switched on at the touch acts for (delta/speed + dt/2). Without this
    every rebound has an error of order (omega dt)^2 (e = 1 rebounds at 1 +- 5e-3 at 16 steps
    per contact)."""
    if law == HERTZ_MINDLIN:
        s = math.sqrt(r_eff * delta)
        root_s = math.sqrt(s)
        elastic = kn * s * delta
        damper = dn * root_s * root_m * un
        kt = kt * s
        ct = dt * root_s * root_m
    else:
        elastic = kn * delta
        damper = dn * root_m * un
        ct = dt * root_m
    if travel > 0.0:
        x = delta + 0.5 * travel
        if law == HERTZ_MINDLIN:
            elastic = 0.4 * kn * math.sqrt(r_eff) * x * x * math.sqrt(x) / travel
        else:
            elastic = 0.5 * kn * x * x / travel
        if grow < 1.0:
            damper *= x / travel
    fn = elastic - damper
    if fn < 0.0:
        fn = 0.0
    return fn, kt, ct


@njit(cache=True, inline="always")
def tangential_spring(x0, x1, x2, vt0, vt1, vt2, n0, n1, n2, kt, ct, mu, fn, dt, ut0, ut1, ut2, end):
    """(F_t (3 values) [N], the new spring (3 values) [m]) of a contact whose spring was x.

    vt: tangential slip velocity at the half step (grows the spring: exact midpoint rule);
    ut: the same at the predicted full step (the dashpot acts at the time of the force);
    end: the weight of a sticking force at the parting (contact_window; 1 elsewhere).
    Arithmetic only (no memory), so that a loop over contacts vectorises."""
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
    else:
        weight = parting_weight(ft2, cap, end)
        f0 *= weight
        f1 *= weight
        f2 *= weight
    return f0, f1, f2, x0, x1, x2


@njit(cache=True, inline="always")
def parting_weight(ft2, cap, end):
    """The weight `end` (contact_window) of a sticking tangential force of squared size ft2 [N^2]
    at the parting, no more than keeps it within the Coulomb cap [N] (a sliding force, mu F_n,
    vanishes at the parting with F_n and needs none)."""
    if ft2 * end * end > cap * cap:
        return cap / math.sqrt(ft2)
    return end


@njit(cache=True, inline="always")
def tangential_force(hist, i, k, vt0, vt1, vt2, n0, n1, n2, kt, ct, mu, fn, dt, ut0, ut1, ut2, end):
    """tangential_spring on the spring hist[i, k] (3,), updated in place; returns F_t [N]."""
    f0, f1, f2, x0, x1, x2 = tangential_spring(
        hist[i, k, 0],
        hist[i, k, 1],
        hist[i, k, 2],
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
        ut0,
        ut1,
        ut2,
        end,
    )
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
def reduced(inv_a, inv_b):
    """The reduced mass m* = 1/(1/m_a + 1/m_b) [kg] (or moment of inertia) of two bodies from
    their inverses, as the integrator moves them: a prescribed body (inverse 0: fixed, driven,
    glued to a wall) leaves the other's own mass, as a wall does; 0 between two prescribed ones,
    whose contact moves nothing."""
    s = inv_a + inv_b
    return 1.0 / s if s > 0.0 else 0.0


@njit(cache=True, inline="always")
def contact_response(n, delta, root_m, r_eff, i_eff, row, law, rolling, spring_dt, step_dt, a, s, p, q, h, w):
    """The whole law of one contact, pairs and walls alike, shared by the CPU blocks
    (kernels/contact.py) and the GPU threads (kernels/cuda_dem.py): from its normal n (from the
    partner to i), overlap delta [m], sqrt of the reduced mass [kg^1/2], R* [m], I* [kg m^2],
    its table row (K_N ... MU_R), v_i - v_j (a) and r_i w_i + r_j w_j (s) at the half step, the
    same predicted (p, q), its spring h [m] and w_i - w_j (w) [rad/s], each a 3-tuple (Numba
    inlines no function of more than about 30 arguments). Returns the force on i (3 values)
    [N], n x F_t (3) [N], the rolling torque on i (3, zero without rolling) [N m] and the new
    spring (3) [m]."""
    n0, n1, n2 = n
    kn, kt, dn, dt, mu, mu_r = row
    s0, s1, s2 = s
    q0, q1, q2 = q
    # contact-point velocity of i relative to the partner: v_i - v_j - (r_i w_i + r_j w_j) x n
    v0 = a[0] - (s1 * n2 - s2 * n1)
    v1 = a[1] - (s2 * n0 - s0 * n2)
    v2 = a[2] - (s0 * n1 - s1 * n0)
    vn = v0 * n0 + v1 * n1 + v2 * n2
    # the same at the predicted full step, for the dashpots
    u0 = p[0] - (q1 * n2 - q2 * n1)
    u1 = p[1] - (q2 * n0 - q0 * n2)
    u2 = p[2] - (q0 * n1 - q1 * n0)
    un = u0 * n0 + u1 * n1 + u2 * n2
    travel, grow, end = contact_window(delta, vn, un, step_dt)
    fn, kt_now, ct = normal_law(kn, kt, dn, dt, law, delta, r_eff, root_m, un, travel, grow)
    g0, g1, g2, x0, x1, x2 = tangential_spring(
        h[0], h[1], h[2], v0 - vn * n0, v1 - vn * n1, v2 - vn * n2, n0, n1, n2, kt_now, ct, mu, fn,
        spring_dt * grow, u0 - un * n0, u1 - un * n1, u2 - un * n2, end,
    )  # fmt: skip
    m0 = 0.0
    m1 = 0.0
    m2 = 0.0
    if rolling and mu_r > 0.0:
        m0, m1, m2 = rolling_torque(w[0], w[1], w[2], n0, n1, n2, mu_r, r_eff, fn, i_eff, step_dt)
    # F_t acts at the contact point x_i - r_i n (on j: x_j + r_j n, with -F_t)
    return (
        fn * n0 + g0, fn * n1 + g1, fn * n2 + g2,
        n1 * g2 - n2 * g1, n2 * g0 - n0 * g2, n0 * g1 - n1 * g0,
        m0, m1, m2, x0, x1, x2,
    )  # fmt: skip
