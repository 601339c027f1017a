"""Energy budget, accumulated every step while the budget is requested: work of gravity and of
moving walls, energy dissipated by the dashpots, by Coulomb sliding and by rolling resistance.

Velocity Verlet changes the kinetic energy (translation and rotation) by exactly
    sum over steps k of F_k . v_k dt,
F_k the force of step k and v_k = v_{k-1/2} + dt/2 a_k the full-step velocity (the two half
kicks of F_k act over (v_{k-1/2} + v_k)/2 and (v_k + v_{k+1/2})/2, whose mean is v_k), up to
half a step at each end. So each contact's work is booked at the full-step relative velocity
w_k of its contact point: this kernel runs after the second half kick (vel = v_k), on copies of
the springs of step k-1 and of the half-step velocities taken before the contact forces, and it
evaluates each contact (the half list: each pair once, in the row of its lower index) with
the law's own functions (normal_law, tangential_force,
rolling_torque of kernels/laws.py) on a scratch copy of its spring, reproducing the force
F_k the contact kernel applied. Per step:
  gravity   m g . v_{k-1/2} dt, exactly the work over the drift x_k - x_{k-1};
  walls     (F_n n + F_t) . V_k dt, the force of the wall on the particle times the wall's
            full-step velocity (0 for a fixed wall); and for a particle moved by prescription
            (inv_mass = 0: fixed, prescribed, glued to a wall), minus the power of the contact
            forces and torques on it at its velocity (gravity does no work on it, and walls do
            not touch it);
  damping   -(F_n - F_e) w_n dt, F_e the elastic normal force (the law at zero velocity), so it
            also books the elastic force the clamp F_n >= 0 cancels; and c_t u_t . w_t dt, the
            tangential dashpot of a sticking contact (u the predicted velocity it acts on);
  friction  k_t (xi_k + xi_{k-1}) . (xi* - xi_k)/2 for a sliding contact: xi* the spring grown
            by the step without the cap, xi_k the capped one, xi_{k-1} the previous one rotated
            into the contact plane (the spring's work k_t xi_k . w_k dt summed by parts is
            Delta(k_t |xi|^2/2) plus this slip term); plus k_t |xi|^2/2 of a spring dropped when
            its pair parts;
  rolling   -M . (w_i - w_j) dt at the full-step spins.
The elastic energies are state functions (kernels/observe/energy.py), so
W_gravity + W_walls = Delta(kinetic + elastic) + damping + friction + rolling holds to the
quadrature of the elastic work (second order, not accumulating) and the overlap's curvature.
For Hertz-Mindlin the tangential energy k_t |xi|^2/2 is not a potential (k_t grows with the
overlap), so the budget closes exactly only for the linear law.

Arguments as in contact.py, walls.py and contact_probe.py; vel_half, angvel_half (N,3) the
half-step velocities; vel, angvel (N,3) the full-step ones [m/s, rad/s]; hist, wall_hist the
springs of the previous step [m]; inv_mass (N,) [1/kg]; wall_vel_half, wall_vel_pred, wall_vel
(W,3) the walls' half-step, predicted and full-step velocities (as the particles') [m/s];
scratch (N,2,3) [m]; booked (N,5) [J] each particle's share of the terms (gravity, walls,
damping, friction, rolling: its own, its walls' and its row's pairs'), accumulated over the
steps; `budget_totals` sums them in particle order, whatever the threads or MPI ranks that
booked them (each particle's share is booked where it is owned, its row as one rank has it).
"""

import math

import numpy as np
from numba import njit, prange

from ..contact_probe import pair_normal, pair_slip, wall_normal, wall_slip
from ..laws import (
    D_N,
    D_T,
    HERTZ_MINDLIN,
    K_N,
    K_T,
    MU,
    MU_R,
    contact_window,
    normal_law,
    parting_weight,
    reduced,
    rolling_torque,
    tangential_force,
)
from ..layout import flat
from ..serial import serial_kernel, serial_twin

GRAVITY = 0
WALLS = 1
DAMPING = 2
FRICTION = 3
ROLLING = 4
TERMS = 5


@njit(cache=True, inline="always")
def _copy(into, values):
    for k in range(values.shape[0]):
        into[k] = values[k]


@njit(cache=True)
def keep_half_step(hist, kept_hist, wall_hist, kept_wall_hist, wall_vel, kept_wall_vel, vel, kept_vel, angvel,
                   kept_angvel):  # fmt: skip
    """What the budget keeps before a step's contact forces (physics/observe/energy_budget.py
    EnergyBudget.forces, and the compiled loops of kernels/steps.py): copies of the springs of
    the last step, of the walls' springs and velocities and of the particles' half-step
    velocities. Every array C-contiguous, each kept one the shape of its source."""
    _copy(flat(kept_hist), flat(hist))
    _copy(flat(kept_wall_hist), flat(wall_hist))
    _copy(flat(kept_wall_vel), flat(wall_vel))
    _copy(flat(kept_vel), flat(vel))
    _copy(flat(kept_angvel), flat(angvel))


# Called, not inlined: with the whole booking inlined into the parallel loop, Numba took 42 s to
# compile accumulate_budget; with the laws of scalars and _tangential called, 14 s, the booking
# as fast (8 000 spheres). book_particle stays inlined: called, it ran 2.6 x slower, its array
# loads no longer known apart from the stores (only a parallel loop's body, or a kernel whose
# arrays are declared distinct, book_particles, tells LLVM so).
@njit(cache=True)
def _normal(kn, kt, dn, dtan, law, delta, r_eff, root_m, un, travel, grow):
    """normal_law, compiled once as a function of scalars rather than inlined at its four calls."""
    return normal_law(kn, kt, dn, dtan, law, delta, r_eff, root_m, un, travel, grow)


@njit(cache=True)
def _rolling(w0, w1, w2, n0, n1, n2, mu_r, r_eff, fn, i_eff, dt):
    """rolling_torque, compiled once like _normal."""
    return rolling_torque(w0, w1, w2, n0, n1, n2, mu_r, r_eff, fn, i_eff, dt)


@njit(cache=True)
def _tangential(
    scratch, i, spring, vt0, vt1, vt2, n0, n1, n2, kt, ct, mu, fn, dt, grow, end, ut0, ut1, ut2, w0, w1, w2
):
    """(F_t (3 values) [N], damping [J], friction [J]) of one contact over the step; the spring
    (3,) is copied into scratch[i] and the law applied there twice: uncapped, then capped.
    w: the full-step relative velocity of the contact point [m/s]; grow, end: the factors of
    contact_window (the force's part beyond the spring's is booked nowhere: it is the
    quadrature of the spring's work at the parting, not a loss)."""
    for a in range(3):
        scratch[i, 0, a] = spring[a]
        scratch[i, 1, a] = spring[a]
    # mu = inf never caps (inf * F_n is inf, or nan for F_n = 0, and no |F_t|^2 exceeds either)
    growth = dt * grow
    tangential_force(
        scratch, i, 0, vt0, vt1, vt2, n0, n1, n2, kt, ct, math.inf, fn, growth, ut0, ut1, ut2, 1.0
    )
    g0, g1, g2 = tangential_force(
        scratch, i, 1, vt0, vt1, vt2, n0, n1, n2, kt, ct, mu, fn, growth, ut0, ut1, ut2, 1.0
    )
    x0 = scratch[i, 1, 0]
    x1 = scratch[i, 1, 1]
    x2 = scratch[i, 1, 2]
    s0 = scratch[i, 0, 0] - x0
    s1 = scratch[i, 0, 1] - x1
    s2 = scratch[i, 0, 2] - x2
    if s0 != 0.0 or s1 != 0.0 or s2 != 0.0:
        # previous spring, rotated: the uncapped spring less the step's growth
        p0 = scratch[i, 0, 0] - vt0 * growth
        p1 = scratch[i, 0, 1] - vt1 * growth
        p2 = scratch[i, 0, 2] - vt2 * growth
        friction = 0.5 * kt * ((x0 + p0) * s0 + (x1 + p1) * s1 + (x2 + p2) * s2)
        return g0, g1, g2, 0.0, friction
    # dashpot force F_t + k_t xi against the full-step slip
    damping = -((g0 + kt * x0) * w0 + (g1 + kt * x1) * w1 + (g2 + kt * x2) * w2) * dt
    weight = parting_weight(g0 * g0 + g1 * g1 + g2 * g2, mu * fn, end)
    return weight * g0, weight * g1, weight * g2, damping, 0.0


# the particles a task of accumulate_budget books (each particle's share is its own: the shares do
# not depend on how the particles are cut into tasks)
BOOKING_CHUNK = 256


@njit(cache=True, parallel=True)
def accumulate_budget(
    pos,
    vel_half,
    angvel_half,
    vel_pred,
    angvel_pred,
    vel,
    angvel,
    radius,
    mass,
    inertia,
    inv_mass,
    inv_inertia,
    material,
    nbr,
    nbr_count,
    start,
    hist,
    table,
    law,
    rolling,
    body_acc,
    length,
    periodic,
    wall_axis,
    wall_sign,
    wall_coord,
    wall_vel_half,
    wall_vel_pred,
    wall_vel,
    wall_table,
    wall_hist,
    dt,
    scratch,
    booked,
    no_spring,
    walls_to_book,
):
    """Add one step's work and dissipation to each particle's share (see the module docstring).
    no_spring (3,) zeros: the spring of every contact when none has friction (read only);
    walls_to_book (N,) uint64: the bit mask of the walls to book for each particle (physics/
    walls.py walls_to_book); the others neither touch it nor hold a spring of it, now or at the
    last step, so they would add zeros. The particles in chunks of BOOKING_CHUNK, each chunk
    booked by book_particles on one thread."""
    particles = (
        pos, vel_half, angvel_half, vel_pred, angvel_pred, vel, angvel, radius, mass, inertia,
        inv_mass, inv_inertia, material,
    )  # fmt: skip
    wall_arrays = (
        wall_axis, wall_sign, wall_coord, wall_vel_half, wall_vel_pred, wall_vel, wall_table, wall_hist,
        wall_hist.shape[0] > 0,
    )  # fmt: skip
    n = pos.shape[0]
    for c in prange((n + BOOKING_CHUNK - 1) // BOOKING_CHUNK):
        first = np.int64(c) * BOOKING_CHUNK  # the prange index is unsigned
        book_particles(
            first, min(first + BOOKING_CHUNK, n), particles, wall_arrays, nbr, nbr_count, start, hist,
            table, law, rolling, body_acc, length, periodic, dt, scratch, booked, no_spring, walls_to_book,
        )  # fmt: skip


# Numba's parallel passes see the few lines above, not the booking: accumulate_budget compiled in
# 14 s with the booking inlined in its prange, and the booking compiles once for any thread count
# (kernels/serial.py serial_kernel). The arrays are the particles', the list's, the walls' and
# the budget's own; it writes only scratch and booked, which share memory with no other.
@serial_kernel(distinct=True)
def book_particles(
    first, last, particles, wall_arrays, nbr, nbr_count, start, hist, table, law, rolling, body_acc,
    length, periodic, dt, scratch, booked, no_spring, walls_to_book,
):  # fmt: skip
    """accumulate_budget for the particles first .. last - 1, one after the other."""
    cap = nbr.shape[1]
    pair_springs = hist.shape[0] > 0
    for i in range(first, last):
        book_particle(
            i, 0, nbr[i], min(nbr_count[i], cap), hist[start[i] :], pair_springs, particles, wall_arrays,
            table, law, rolling, body_acc, length, periodic, dt, scratch, booked, no_spring, walls_to_book[i],
        )  # fmt: skip


@njit(cache=True, inline="always")
def book_particle(
    i, lowest, partners, count, row_springs, pair_springs, particles, wall_arrays, table, law, rolling,
    body_acc, length, periodic, dt, scratch, booked, no_spring, to_book,
):  # fmt: skip
    """Particle i's share of one step: partners[:count] its listed partners (those below `lowest`
    left out: the GPU's full rows), row_springs[k] the spring of partner k at the last step
    (read when pair_springs); `particles` and `wall_arrays` the arrays of accumulate_budget (the
    arguments of one call stay under the 30 that CPython passes one by one, which Numba's
    inlining needs), wall_hist[i, w] a wall spring (read when wall_springs); no_spring a (3,)
    zero; to_book: the bit mask of the walls to book (all ones: every wall)."""
    pos, vel_half, angvel_half, vel_pred, angvel_pred, vel, angvel = particles[:7]
    radius, mass, inertia, inv_mass, inv_inertia, material = particles[7:]
    wall_axis, wall_sign, wall_coord, wall_vel_half, wall_vel_pred, wall_vel = wall_arrays[:6]
    wall_table, wall_hist, wall_springs = wall_arrays[6:]
    single = table.shape[0] == 1
    wall_single = wall_table.shape[1] == 1
    ri = radius[i]
    mi = mass[i]
    ci = 0 if single else material[i]
    driven = inv_mass[i] == 0.0  # moved by prescription, not by forces
    gravity = 0.0
    if not driven:
        gravity = (
            dt
            * mi
            * (body_acc[0] * vel_half[i, 0] + body_acc[1] * vel_half[i, 1] + body_acc[2] * vel_half[i, 2])
        )
    walls = 0.0
    # force and torque of its contacts on a driven particle i (its work is the boundary's)
    f0 = 0.0
    f1 = 0.0
    f2 = 0.0
    t0 = 0.0
    t1 = 0.0
    t2 = 0.0
    damping = 0.0
    friction = 0.0
    roll = 0.0
    for k in range(count):
        j = partners[k]
        if j < lowest:  # (a full row's partners below i: their own rows book them)
            continue
        row = table[0, 0] if single else table[ci, material[j]]
        touching, n0, n1, n2, delta = pair_normal(pos, radius, i, j, length, periodic)
        if not touching:
            # a parting pair's spring is dropped (Hertz: k_t = 0 at touch; none without friction)
            if law != HERTZ_MINDLIN and pair_springs:
                xi2 = row_springs[k, 0] ** 2 + row_springs[k, 1] ** 2 + row_springs[k, 2] ** 2
                friction += 0.5 * row[K_T] * xi2
            continue
        rj = radius[j]
        v0, v1, v2 = pair_slip(vel_half, angvel_half, i, j, ri, rj, n0, n1, n2)
        vn = v0 * n0 + v1 * n1 + v2 * n2
        u0, u1, u2 = pair_slip(vel_pred, angvel_pred, i, j, ri, rj, n0, n1, n2)
        un = u0 * n0 + u1 * n1 + u2 * n2
        w0, w1, w2 = pair_slip(vel, angvel, i, j, ri, rj, n0, n1, n2)
        wn = w0 * n0 + w1 * n1 + w2 * n2
        root_m = math.sqrt(reduced(inv_mass[i], inv_mass[j]))
        r_eff = ri * rj / (ri + rj)
        travel, grow, end = contact_window(delta, vn, un, dt)
        kn, kt, dn, dtan = row[K_N], row[K_T], row[D_N], row[D_T]
        fe = _normal(kn, kt, dn, dtan, law, delta, r_eff, root_m, 0.0, travel, grow)[0]
        fn, kt, ct = _normal(kn, kt, dn, dtan, law, delta, r_eff, root_m, un, travel, grow)
        spring = row_springs[k] if pair_springs else no_spring
        g0, g1, g2, d_t, f_t = _tangential(
            scratch, i, spring, v0 - vn * n0, v1 - vn * n1, v2 - vn * n2, n0, n1, n2, kt, ct,
            row[MU], fn, dt, grow, end, u0 - un * n0, u1 - un * n1, u2 - un * n2, w0, w1, w2,
        )  # fmt: skip
        damping += -(fn - fe) * wn * dt + d_t
        friction += f_t
        # force on i (on j: its negative); torques r n x F_t of both, and the rolling pair
        c0 = fn * n0 + g0
        c1 = fn * n1 + g1
        c2 = fn * n2 + g2
        x0 = n1 * g2 - n2 * g1
        x1 = n2 * g0 - n0 * g2
        x2 = n0 * g1 - n1 * g0
        m0 = 0.0
        m1 = 0.0
        m2 = 0.0
        if rolling and row[MU_R] > 0.0:
            m0, m1, m2 = _rolling(
                angvel_half[i, 0] - angvel_half[j, 0],
                angvel_half[i, 1] - angvel_half[j, 1],
                angvel_half[i, 2] - angvel_half[j, 2],
                n0, n1, n2, row[MU_R], r_eff, fn, reduced(inv_inertia[i], inv_inertia[j]), dt,
            )  # fmt: skip
            r0 = angvel[i, 0] - angvel[j, 0]
            r1 = angvel[i, 1] - angvel[j, 1]
            r2 = angvel[i, 2] - angvel[j, 2]
            roll -= (m0 * r0 + m1 * r1 + m2 * r2) * dt
        # the work a driven particle does on the other: minus that of the contact on it
        if driven:
            f0 += c0
            f1 += c1
            f2 += c2
            t0 += m0 - ri * x0
            t1 += m1 - ri * x1
            t2 += m2 - ri * x2
        if inv_mass[j] == 0.0:
            walls += (c0 * vel[j, 0] + c1 * vel[j, 1] + c2 * vel[j, 2]) * dt
            walls -= ((-m0 - rj * x0) * angvel[j, 0] + (-m1 - rj * x1) * angvel[j, 1]) * dt
            walls -= (-m2 - rj * x2) * angvel[j, 2] * dt
    if driven:
        walls -= (f0 * vel[i, 0] + f1 * vel[i, 1] + f2 * vel[i, 2]) * dt
        walls -= (t0 * angvel[i, 0] + t1 * angvel[i, 1] + t2 * angvel[i, 2]) * dt
    for w in range(wall_axis.shape[0]):
        if driven:
            break  # walls neither touch nor push driven particles
        if not (to_book >> np.uint64(w)) & np.uint64(1):
            continue  # neither touching nor holding a spring, now or at the last step: zeros
        row = wall_table[w, 0] if wall_single else wall_table[w, material[i]]
        touching, n0, n1, n2, delta = wall_normal(pos, radius, i, w, wall_axis, wall_sign, wall_coord)
        if not touching:
            if law != HERTZ_MINDLIN and wall_springs:
                xi2 = wall_hist[i, w, 0] ** 2 + wall_hist[i, w, 1] ** 2 + wall_hist[i, w, 2] ** 2
                friction += 0.5 * row[K_T] * xi2
            continue
        wv0 = wall_vel[w, 0]
        wv1 = wall_vel[w, 1]
        wv2 = wall_vel[w, 2]
        h0 = wall_vel_half[w, 0]
        h1 = wall_vel_half[w, 1]
        h2 = wall_vel_half[w, 2]
        v0, v1, v2 = wall_slip(vel_half, angvel_half, i, ri, n0, n1, n2, h0, h1, h2)
        vn = v0 * n0 + v1 * n1 + v2 * n2
        p0 = wall_vel_pred[w, 0]
        p1 = wall_vel_pred[w, 1]
        p2 = wall_vel_pred[w, 2]
        u0, u1, u2 = wall_slip(vel_pred, angvel_pred, i, ri, n0, n1, n2, p0, p1, p2)
        un = u0 * n0 + u1 * n1 + u2 * n2
        w0, w1, w2 = wall_slip(vel, angvel, i, ri, n0, n1, n2, wv0, wv1, wv2)
        wn = w0 * n0 + w1 * n1 + w2 * n2
        root_m = math.sqrt(mi)
        travel, grow, end = contact_window(delta, vn, un, dt)
        kn, kt, dn, dtan = row[K_N], row[K_T], row[D_N], row[D_T]
        fe = _normal(kn, kt, dn, dtan, law, delta, ri, root_m, 0.0, travel, grow)[0]
        fn, kt, ct = _normal(kn, kt, dn, dtan, law, delta, ri, root_m, un, travel, grow)
        spring = wall_hist[i, w] if wall_springs else no_spring
        g0, g1, g2, d_t, f_t = _tangential(
            scratch, i, spring, v0 - vn * n0, v1 - vn * n1, v2 - vn * n2, n0, n1, n2, kt,
            ct, row[MU], fn, dt, grow, end, u0 - un * n0, u1 - un * n1, u2 - un * n2, w0, w1, w2,
        )  # fmt: skip
        walls += ((fn * n0 + g0) * wv0 + (fn * n1 + g1) * wv1 + (fn * n2 + g2) * wv2) * dt
        damping += -(fn - fe) * wn * dt + d_t
        friction += f_t
        if rolling and row[MU_R] > 0.0:
            m0, m1, m2 = _rolling(
                angvel_half[i, 0], angvel_half[i, 1], angvel_half[i, 2],
                n0, n1, n2, row[MU_R], ri, fn, inertia[i], dt,
            )  # fmt: skip
            roll -= (m0 * angvel[i, 0] + m1 * angvel[i, 1] + m2 * angvel[i, 2]) * dt
    booked[i, GRAVITY] += gravity
    booked[i, WALLS] += walls
    booked[i, DAMPING] += damping
    booked[i, FRICTION] += friction
    booked[i, ROLLING] += roll


@njit(cache=True)
def budget_totals(booked, totals):
    """totals (5,) [J]: the particles' shares summed in particle order."""
    for t in range(TERMS):
        totals[t] = 0.0
    for i in range(booked.shape[0]):
        for t in range(TERMS):
            totals[t] += booked[i, t]


# one thread: the booking without a parallel region (kernels/serial.py); it writes only its
# scratch and the shares, which no other argument shares
accumulate_budget_serial = serial_twin(accumulate_budget, distinct=True)
