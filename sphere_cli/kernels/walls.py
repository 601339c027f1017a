"""Plane walls on the faces of the box: their contact with particles and their motion.

Contact: the law of `laws.py` (linear or Hertz-Mindlin, tangential spring with Coulomb cap,
optional rolling resistance) against a body of infinite mass and radius moving at the wall's
velocity: m* = m_i, R* = r_i, I* = I_i, relative spin w_i, relative velocity v_i - V_w.
Particles that do not move by forces (inv_mass = 0: fixed, prescribed or glued to a wall)
neither touch walls nor push them.

Motion (velocity Verlet like the particles, kernels/motion.py), per wall w and direction:
fixed, prescribed velocity, or driven by a force balance. With inward normal n, area A, contact
force F of the particles on the wall, mass M and damping C:
    M dV_n/dt = A sigma(t) + F.n - C V_n,    sigma(t) = sigma_0 + sigma_a sin(omega t + phi),
so the wall rests only where the contact stress -F.n/A equals the target. Tangentially, along
the shear axis t: M dV_t/dt = A tau + F.t - C V_t (tau: the traction on the particles). The
damping is implicit in the second half kick, so only the undamped wall-contact frequency
limits the step.

Arguments: pos, vel, angvel, vel_pred, angvel_pred (N,3); radius, mass, inertia, inv_mass (N,);
material (N,) int32; wall_axis (W,) int64 axis of the normal; wall_sign (W,) +1.0 on a lower face
(normal along +axis), -1.0 on an upper face; wall_coord (W,) [m]; wall_vel, wall_vel_pred (W,3)
[m/s]; wall_table (W,M,6) parameters of wall w against material m, columns as in laws.py (the
wall's own elasticity, if any, is in E* and G*; a rigid wall has none); wall_hist (N,W,3) [m]
(no rows when no contact has friction);
force, torque (N,3) accumulated in place; springs (N,) uint64 bit mask of the walls whose spring
with particle i may be non-zero (W <= 64); record (W,) uint8: for the walls marked, also store
each particle's wall force in pforce (N,W,3) [N] (their reaction, summed by wall_totals);
mode (W,2) int64 normal mode (FIXED, VELOCITY, STRESS) and shear mode (FIXED = none, VELOCITY,
STRESS); control (W,NC) columns C_*; attached (K,) int64 particles glued to wall attached_wall
(K,) int64. The particles' (N,3) arrays must be C-contiguous: the contact kernel reads them
through flat views (kernels/layout.py).
"""

import math

import numpy as np
from numba import njit, prange

from .contact import (
    B_A0,
    B_A1,
    B_A2,
    B_C0,
    B_C1,
    B_C2,
    B_DELTA,
    B_E0,
    B_E1,
    B_E2,
    B_H0,
    B_H1,
    B_H2,
    B_II,
    B_M0,
    B_M1,
    B_M2,
    B_MI,
    B_N0,
    B_N1,
    B_N2,
    B_P0,
    B_P1,
    B_P2,
    B_Q0,
    B_Q1,
    B_Q2,
    B_RI,
    B_ROW,
    B_S0,
    B_S1,
    B_S2,
    B_W0,
    B_W1,
    B_W2,
    BLOCK,
    ZERO,
    from_block,
    to_block,
    wall_law,
)
from .contact_probe import wall_normal
from .exact_sum import WORDS, add_exact, exact_value
from .laws import COLUMNS
from .layout import U1, U2, U3, flat, prefetch, prefetch_particle
from .serial import positions, serial_kernel

FIXED = 0
VELOCITY = 1
STRESS = 2
# columns of the control table
C_VELOCITY = 0  # normal velocity into the box [m/s]
C_STRESS = 1  # mean target normal stress [Pa]
C_AMPLITUDE = 2  # amplitude of its sine [Pa]
C_OMEGA = 3  # angular frequency [rad/s]
C_PHASE = 4  # phase at the start of the stage [rad]
C_MASS = 5  # [kg]
C_DAMPING = 6  # damping coefficient C [kg/s]
C_SHEAR_AXIS = 7  # axis index of the tangential drive
C_SHEAR = 8  # tangential velocity [m/s] or target shear traction [Pa]
C_START = 9  # time the stage started [s]
NC = 10
# how many listed particles ahead of the one being measured wall_forces prefetches a particle's
# lines on a bed beyond the cache (`warm`): the near-wall particles are spread over the whole
# index range, so each brings its own lines from memory (100 000 spheres, the wall kernel alone
# after a pair sweep, one thread: 3.9-4.1 -> 3.1-3.3 ns a particle of the bed)
WALL_PREFETCH_AHEAD = 16


@njit(cache=True)
def spring_bits(hist, bits):
    """bits[i]: bit w set where particle i's spring on wall w may be set (hist (N, W, 3)): any
    component non-zero, or -0.0, as a run that set it leaves it."""
    for i in range(hist.shape[0]):
        held = np.uint64(0)
        for w in range(hist.shape[1]):
            for a in range(3):
                if hist[i, w, a] != 0.0 or math.copysign(1.0, hist[i, w, a]) < 0.0:
                    held |= np.uint64(1) << np.uint64(w)
        bits[i] = held


@njit(cache=True)
def _flush_walls(
    buf, ids, count, law, rolling, spring_dt, step_dt, radius, wall_hist, force, torque, record, pforce
):
    """The law for a block of wall contacts, then each particle's contacts summed in wall order
    and added to its force and torque (a particle's contacts are never split between blocks)."""
    wall_law(buf, count, law, rolling, spring_dt, step_dt)
    b = np.uint64(0)
    end = np.uint64(count)
    while b < end:
        i = ids[b]
        i3 = U3 * i
        ri = radius[i]
        f0 = 0.0
        f1 = 0.0
        f2 = 0.0
        t0 = 0.0
        t1 = 0.0
        t2 = 0.0
        while b < end and ids[b] == i:
            w = ids[np.uint64(BLOCK) + b]
            if wall_hist.shape[0] > 0:
                wall_hist[i, w, 0] = from_block(buf, B_H0, b)
                wall_hist[i, w, 1] = from_block(buf, B_H1, b)
                wall_hist[i, w, 2] = from_block(buf, B_H2, b)
            e0 = from_block(buf, B_E0, b)
            e1 = from_block(buf, B_E1, b)
            e2 = from_block(buf, B_E2, b)
            f0 += e0
            f1 += e1
            f2 += e2
            if record[w]:
                pforce[i, w, 0] = e0
                pforce[i, w, 1] = e1
                pforce[i, w, 2] = e2
            t0 -= ri * from_block(buf, B_C0, b)
            t1 -= ri * from_block(buf, B_C1, b)
            t2 -= ri * from_block(buf, B_C2, b)
            if rolling:
                t0 += from_block(buf, B_M0, b)
                t1 += from_block(buf, B_M1, b)
                t2 += from_block(buf, B_M2, b)
            b += np.uint64(1)
        force[i3] += f0
        force[i3 + U1] += f1
        force[i3 + U2] += f2
        torque[i3] += t0
        torque[i3 + U1] += t1
        torque[i3 + U2] += t2


# every array argument is an array of its own (physics/walls.py PlaneWallForces._arguments)
@serial_kernel(distinct=True)
def wall_forces_serial(
    pos,
    vel,
    angvel,
    vel_pred,
    angvel_pred,
    radius,
    mass,
    inertia,
    inv_mass,
    material,
    wall_axis,
    wall_sign,
    wall_coord,
    wall_vel,
    wall_vel_pred,
    wall_table,
    wall_hist,
    law,
    rolling,
    spring_dt,
    step_dt,
    force,
    torque,
    record,
    pforce,
    springs,
    near,
    reach,
    pieces,
    blocks,
    block_ids,
    warm,
):
    """Add the forces and torques of W plane walls on the particles listed in `near` (every
    particle that can touch a wall, see near_walls; reach (>= len(near),) uint64: bit w set where
    near[m] can touch wall w, the only walls tested) to force/torque, and store those of the walls
    marked in record in pforce. springs (N,) uint64: bit w set where wall_hist[i, w] may be
    non-zero (kept up to date here), so a particle away from the walls reads one word instead of
    its W springs. The touching pairs go through blocks like the pair contacts (kernels/
    contact.py): pieces (T+1,) int64 cut `near` into one piece per thread, blocks (T,
    FIELDS*BLOCK) and block_ids (T, 2*BLOCK) uint64 (particle, wall) are their scratch. warm:
    prefetch the lines of the particle WALL_PREFETCH_AHEAD places on in `near` (a hint: no value
    changes), on a bed beyond the cache (physics/contact.py beyond_cache). The pieces one after
    the other: one thread's kernel, which wall_forces calls for each piece on its thread
    (kernels/serial.py serial_kernel)."""
    nw = wall_axis.shape[0]
    single = wall_table.shape[1] == 1
    vel, angvel, vel_pred, angvel_pred = flat(vel), flat(angvel), flat(vel_pred), flat(angvel_pred)
    force, torque = flat(force), flat(torque)
    pos_line, hist_line, hist_row = flat(pos), flat(wall_hist), np.uint64(3 * nw)
    recording = False
    for w in range(nw):
        recording = recording or record[w] != 0
    for c in range(pieces.shape[0] - 1):
        buf = blocks[c]
        ids = block_ids[c]
        filled = ZERO
        for m in range(pieces[c], pieces[c + 1]):
            if warm and m + WALL_PREFETCH_AHEAD < pieces[c + 1]:
                k = np.uint64(near[m + WALL_PREFETCH_AHEAD])
                vectors = (pos_line, vel, angvel, vel_pred, angvel_pred, force, torque)
                prefetch_particle(k, vectors, (radius, mass, inv_mass))
                prefetch(material, k)
                prefetch(springs, k)
                if wall_hist.shape[0] > 0:
                    prefetch(hist_line, hist_row * k)
            i = np.uint64(near[m])
            i3 = U3 * i
            if recording:
                for w in range(nw):
                    if record[w]:
                        pforce[i, w, 0] = 0.0
                        pforce[i, w, 1] = 0.0
                        pforce[i, w, 2] = 0.0
            if inv_mass[i] == 0.0:
                continue
            if filled + nw > BLOCK:  # room for all of this particle's walls
                _flush_walls(
                    buf, ids, filled, law, rolling, spring_dt, step_dt, radius, wall_hist, force, torque,
                    record, pforce,
                )  # fmt: skip
                filled = ZERO
            ri = radius[i]
            ci = np.uint64(0 if single else material[i])
            held = springs[i]
            walls = reach[m]
            for wall in range(nw):
                w = np.uint64(wall)  # unsigned indices: no negative-index wraparound code
                bit = np.uint64(1) << w
                if not walls & bit:
                    continue
                touching, n0, n1, n2, delta = wall_normal(pos, radius, i, w, wall_axis, wall_sign, wall_coord)
                if not touching:
                    if held & bit:  # the contact has ended: its spring is gone
                        if wall_hist.shape[0] > 0:  # (none without friction)
                            wall_hist[i, w, 0] = 0.0
                            wall_hist[i, w, 1] = 0.0
                            wall_hist[i, w, 2] = 0.0
                        held &= ~bit
                    continue
                held |= bit
                b = np.uint64(filled)
                ids[b] = i
                ids[np.uint64(BLOCK) + b] = w
                to_block(buf, B_N0, b, n0)
                to_block(buf, B_N1, b, n1)
                to_block(buf, B_N2, b, n2)
                to_block(buf, B_DELTA, b, delta)
                # the wall as the partner j: its velocity, no spin
                to_block(buf, B_A0, b, vel[i3] - wall_vel[w, 0])
                to_block(buf, B_A1, b, vel[i3 + U1] - wall_vel[w, 1])
                to_block(buf, B_A2, b, vel[i3 + U2] - wall_vel[w, 2])
                to_block(buf, B_S0, b, ri * angvel[i3])
                to_block(buf, B_S1, b, ri * angvel[i3 + U1])
                to_block(buf, B_S2, b, ri * angvel[i3 + U2])
                to_block(buf, B_P0, b, vel_pred[i3] - wall_vel_pred[w, 0])
                to_block(buf, B_P1, b, vel_pred[i3 + U1] - wall_vel_pred[w, 1])
                to_block(buf, B_P2, b, vel_pred[i3 + U2] - wall_vel_pred[w, 2])
                to_block(buf, B_Q0, b, ri * angvel_pred[i3])
                to_block(buf, B_Q1, b, ri * angvel_pred[i3 + U1])
                to_block(buf, B_Q2, b, ri * angvel_pred[i3 + U2])
                to_block(buf, B_MI, b, mass[i])
                to_block(buf, B_RI, b, ri)
                if wall_hist.shape[0] > 0:
                    to_block(buf, B_H0, b, wall_hist[i, w, 0])
                    to_block(buf, B_H1, b, wall_hist[i, w, 1])
                    to_block(buf, B_H2, b, wall_hist[i, w, 2])
                else:  # frictionless: no springs
                    to_block(buf, B_H0, b, 0.0)
                    to_block(buf, B_H1, b, 0.0)
                    to_block(buf, B_H2, b, 0.0)
                if rolling:
                    to_block(buf, B_W0, b, angvel[i3])
                    to_block(buf, B_W1, b, angvel[i3 + U1])
                    to_block(buf, B_W2, b, angvel[i3 + U2])
                    to_block(buf, B_II, b, inertia[i])
                for col in range(COLUMNS):
                    to_block(buf, B_ROW + col, b, wall_table[w, ci, col])
                filled += 1
            springs[i] = held
        _flush_walls(
            buf,
            ids,
            filled,
            law,
            rolling,
            spring_dt,
            step_dt,
            radius,
            wall_hist,
            force,
            torque,
            record,
            pforce,
        )


@njit(cache=True)
def near_walls(
    pos, radius, inv_mass, wall_axis, wall_sign, wall_coord, margin, springs, wall_hist, near, reach, to_book
):
    """List in `near` the particles that move by forces and lie within their radius + margin
    of some wall, and in `reach` (uint64) the bit mask of those walls; return how many. A wall
    left out cannot touch the particle until it, or the wall, has moved margin/2 (the caller
    rebuilds the list before that); its spring is cleared here (a particle that jumped away
    within one step keeps none). to_book (N,) uint64: for every particle, the walls in reach and
    those whose spring was cleared here (the energy budget books a parting spring from its copy
    of the last step's, physics/observe/energy_budget.py)."""
    count = 0
    for i in range(pos.shape[0]):
        close = np.uint64(0)
        if inv_mass[i] != 0.0:
            for w in range(wall_axis.shape[0]):
                gap = wall_sign[w] * (pos[i, wall_axis[w]] - wall_coord[w])
                if gap < radius[i] + margin:
                    close |= np.uint64(1) << np.uint64(w)
        if close != 0:
            near[count] = i
            reach[count] = close
            count += 1
        far = springs[i] & ~close
        to_book[i] = close | far
        if far != 0:
            springs[i] &= close
            # the springs of the walls out of reach are gone (none without friction)
            for w in range(wall_axis.shape[0] if wall_hist.shape[0] > 0 else 0):
                if far & (np.uint64(1) << np.uint64(w)):
                    wall_hist[i, w, 0] = 0.0
                    wall_hist[i, w, 1] = 0.0
                    wall_hist[i, w, 2] = 0.0
    return count


@njit(cache=True)
def wall_kick_drift(
    wall_axis, wall_sign, mode, control, coord, vel, acc, vel_pred, shift, dt, attached, attached_wall, pvel
):
    """First half kick and drift of every wall (fixed and prescribed directions are set, driven
    ones kicked with the last acceleration); the glued particles take their wall's velocity."""
    half = 0.5 * dt
    for w in range(wall_axis.shape[0]):
        a = wall_axis[w]
        t = int(control[w, C_SHEAR_AXIS])
        for b in range(3):
            m = mode[w, 0] if b == a else (mode[w, 1] if b == t else FIXED)
            if m == FIXED:
                vel[w, b] = 0.0
                acc[w, b] = 0.0
            elif m == VELOCITY:
                vel[w, b] = wall_sign[w] * control[w, C_VELOCITY] if b == a else control[w, C_SHEAR]
                acc[w, b] = 0.0
            else:
                vel[w, b] += half * acc[w, b]
            vel_pred[w, b] = vel[w, b] + half * acc[w, b]
            shift[w, b] += dt * vel[w, b]
        coord[w] += dt * vel[w, a]
    for k in range(attached.shape[0]):
        w = attached_wall[k]
        for b in range(3):
            pvel[attached[k], b] = vel[w, b]


@njit(cache=True)
def wall_areas(wall_axis, wall_sign, coord, lower, upper, area):
    """Area [m^2] of each wall: the product of the box's extents along the other two axes, each
    bounded by the walls on that axis where there are walls (they may move)."""
    lo0 = lower[0]
    lo1 = lower[1]
    lo2 = lower[2]
    hi0 = upper[0]
    hi1 = upper[1]
    hi2 = upper[2]
    for w in range(wall_axis.shape[0]):
        a = wall_axis[w]
        if wall_sign[w] > 0.0:
            if a == 0:
                lo0 = coord[w]
            elif a == 1:
                lo1 = coord[w]
            else:
                lo2 = coord[w]
        elif a == 0:
            hi0 = coord[w]
        elif a == 1:
            hi1 = coord[w]
        else:
            hi2 = coord[w]
    for w in range(wall_axis.shape[0]):
        a = wall_axis[w]
        if a == 0:
            area[w] = (hi1 - lo1) * (hi2 - lo2)
        elif a == 1:
            area[w] = (hi0 - lo0) * (hi2 - lo2)
        else:
            area[w] = (hi0 - lo0) * (hi1 - lo1)


# The particles' force on a wall is summed exactly (kernels/exact_sum.py): sums (W, 3, WORDS)
# int64 holds, for each wall and direction, the words of the sum. Exact, it is the same on any
# number of threads, on MPI ranks that add their own particles' words with MPI_SUM
# (kernels/rank_messages.py rank_wall_totals), and on a GPU (kernels/cuda_dem.py, integer
# atomics); and the message between ranks is these words, whatever the number of particles.


@njit(cache=True)
def clear_sums(sums):
    for w in range(sums.shape[0]):
        for b in range(3):
            for k in range(WORDS):
                sums[w, b, k] = 0


@njit(cache=True, inline="always")
def add_pushes(pforce, i, record, sums):
    """Particle i's push on each wall marked in record (minus the wall's force on it) into sums."""
    for w in range(record.shape[0]):
        if record[w]:
            for b in range(3):
                add_exact(sums[w, b], -pforce[i, w, b])


@njit(cache=True)
def add_glued(attached, attached_wall, pforce_total, mass, body_acc, record, sums):
    """The contact forces on the particles glued to each wall marked in record (their total
    force pforce_total less their weight) into sums."""
    for k in range(attached.shape[0]):
        i = attached[k]
        w = attached_wall[k]
        if record[w]:
            for b in range(3):
                add_exact(sums[w, b], pforce_total[i, b] - mass[i] * body_acc[b])


@njit(cache=True)
def finish_wall_totals(sums, record, fluid_force, wall_force):
    """Force on each wall [N]: that of the pore fluid (fluid_force (W,3), zero but for a wall
    bounding a Darcy fluid) plus, on each wall marked in record, that of the particles, the sum
    in sums (add_pushes, add_glued; normalised in place)."""
    for w in range(wall_force.shape[0]):
        for b in range(3):
            wall_force[w, b] = fluid_force[w, b] + exact_value(sums[w, b]) if record[w] else fluid_force[w, b]


@njit(cache=True)
def wall_totals(
    pforce, record, sums, attached, attached_wall, pforce_total, mass, body_acc, fluid_force, wall_force
):  # fmt: skip
    """finish_wall_totals from each particle's wall forces pforce (N,W,3) and the glued
    particles (sums its scratch)."""
    clear_sums(sums)
    for i in range(pforce.shape[0]):
        add_pushes(pforce, i, record, sums)
    add_glued(attached, attached_wall, pforce_total, mass, body_acc, record, sums)
    finish_wall_totals(sums, record, fluid_force, wall_force)


@njit(cache=True)
def listed_wall_totals(
    listed, pforce, record, sums, attached, attached_wall, pforce_total, mass, body_acc, fluid_force,
    wall_force,
):  # fmt: skip
    """wall_totals, bitwise, from the rows of the particles listed near the walls (wall_forces
    writes no other row, and the rows are zeroed when the list is made), not every particle's:
    at 100 000 spheres, 0.85 ms a step less than the dense pass over pforce."""
    clear_sums(sums)
    for i in listed:
        add_pushes(pforce, i, record, sums)
    add_glued(attached, attached_wall, pforce_total, mass, body_acc, record, sums)
    finish_wall_totals(sums, record, fluid_force, wall_force)


@njit(cache=True)
def wall_kick(wall_axis, wall_sign, mode, control, wall_force, area, vel, acc, time, dt):
    """Second half kick of the driven directions from the force balance (module docstring) at
    `time` [s], with the damping implicit: V_{n+1} = (V_{n+1/2} + dt/2 (A target + F)/M) /
    (1 + dt/2 C/M); then a_{n+1} = (A target + F - C V_{n+1})/M for the next first half kick."""
    half = 0.5 * dt
    for w in range(wall_axis.shape[0]):
        a = wall_axis[w]
        s = wall_sign[w]
        mass = control[w, C_MASS]
        relax = 1.0 + half * control[w, C_DAMPING] / mass
        if mode[w, 0] == STRESS:
            phase = control[w, C_OMEGA] * (time - control[w, C_START]) + control[w, C_PHASE]
            target = control[w, C_STRESS] + control[w, C_AMPLITUDE] * math.sin(phase)
            drive = area[w] * target + s * wall_force[w, a]  # along the inward normal
            inward = (s * vel[w, a] + half * drive / mass) / relax
            vel[w, a] = s * inward
            acc[w, a] = s * (drive - control[w, C_DAMPING] * inward) / mass
        if mode[w, 1] == STRESS:
            t = int(control[w, C_SHEAR_AXIS])
            drive = area[w] * control[w, C_SHEAR] + wall_force[w, t]
            vel[w, t] = (vel[w, t] + half * drive / mass) / relax
            acc[w, t] = (drive - control[w, C_DAMPING] * vel[w, t]) / mass


# where wall_forces takes the particles near the walls, its pieces of them and their scratch
NEAR, PIECES, WALL_BLOCKS, WALL_BLOCK_IDS = positions(
    wall_forces_serial, "near", "pieces", "blocks", "block_ids"
)
AFTER_WALL_SCRATCH = WALL_BLOCK_IDS + 1


@njit(cache=True)
def one_piece(walls, c):
    """wall_forces's arguments `walls` for its piece c alone (its bounds in `near` and its rows
    of the scratch), which wall_forces_serial takes on its own (wall_forces, kernels/steps.py
    chunk_steps_end)."""
    pieces, blocks, ids = walls[PIECES], walls[WALL_BLOCKS], walls[WALL_BLOCK_IDS]
    piece = (pieces[c : c + 2], blocks[c : c + 1], ids[c : c + 1])
    return walls[:PIECES] + piece + walls[AFTER_WALL_SCRATCH:]


@njit(cache=True, parallel=True)
def wall_forces(
    pos, vel, angvel, vel_pred, angvel_pred, radius, mass, inertia, inv_mass, material, wall_axis,
    wall_sign, wall_coord, wall_vel, wall_vel_pred, wall_table, wall_hist, law, rolling, spring_dt,
    step_dt, force, torque, record, pforce, springs, near, reach, pieces, blocks, block_ids, warm,
):  # fmt: skip
    """wall_forces_serial on several threads, piece c of `near` on one of them (a particle is
    listed once: each piece's particles and scratch are its own)."""
    walls = (
        pos, vel, angvel, vel_pred, angvel_pred, radius, mass, inertia, inv_mass, material, wall_axis,
        wall_sign, wall_coord, wall_vel, wall_vel_pred, wall_table, wall_hist, law, rolling, spring_dt,
        step_dt, force, torque, record, pforce, springs, near, reach, pieces, blocks, block_ids, warm,
    )  # fmt: skip
    for c in prange(pieces.shape[0] - 1):
        wall_forces_serial(*one_piece(walls, c))
