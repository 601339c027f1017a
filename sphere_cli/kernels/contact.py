"""Particle-particle contacts: the pair sweep that evaluates the contact law of kernels/laws.py
for every touching pair.

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

Blocks: the law is evaluated for BLOCK touching pairs at a time. A scalar sweep finds them and
copies the law's inputs into a block (one row of BLOCK values per quantity: row f of contact c is
buf[f * BLOCK + c]); contact_law evaluates the whole block in one loop, which the compiler
vectorises (4 contacts per instruction with AVX2: the rows are contiguous, a constant BLOCK
apart, and the law is arithmetic only, its branches become masks); a scalar sweep then applies
the results in the block's order, which is the sweep's. Each contact gets the same operations
in the same order as a contact-by-contact evaluation, so the forces are bitwise the same; the
pairs across chunks go through the same blocks and law.

Finding the touching pairs: about half of the listed pairs touch (1.55 of 3.44 a row in the
settled bed), in no pattern a branch predictor can learn, so a sweep that branches on each
pair's test loses a mispredicted branch every other pair, and a loop over each row's few pairs
another at each row's end. The sweep therefore takes the chunk's listed pairs in their packed
order (the springs'), BLOCK at a time whatever their rows (pair_row, pair_partner: pack_pairs),
measures them in one loop without a branch per pair that lists the touching ones and clears the
springs of the others (touching_pairs), then copies only those into the block. The pair sweep of
the settled bed, one thread (docs/performance.md): 63 -> 50 ns a particle at 10 000.

Arguments: pos, vel, angvel, vel_pred, angvel_pred (N,3) [m, m/s, rad/s]; radius, inv_mass,
inv_inertia (N,) [m, 1/kg, 1/(kg m^2)] (0 for a prescribed particle: the reduced mass of its
contacts is the other's mass, `reduced`); mass (N,) [kg] for m g; material (N,) int32 index
into the table; nbr (N,C) int32 half rows, nbr_count (N,); start (N+1,) int64 row starts and
hist (>= P,3) [m] the packed springs (pair (i, nbr[i, k]) at start[i] + k); rev (N,R) int32
reverse slots, rev_count (N,) (kernels/neighbors.py); pair_row, pair_partner (>= P,) int32 the
listed pairs in that order (pack_pairs); warm: whether to prefetch the listed pairs' partners
ahead (touching_pairs); bounds (T+1,) int64 chunk boundaries (chunk c: bounds[c] <= i <
bounds[c+1]); table (M,M,6) per pair of materials, the columns K_N, K_T, D_N, D_T, MU, MU_R of
kernels/laws.py; law: the law code (kernels/laws.py), rolling: the rolling-resistance flag;
body_acc (3,) [m/s^2] (gravity); length (3,) [m], periodic (3,) uint8; spring_dt [s] (the
tangential spring's growth, 0 for the forces of the initial state), step_dt [s] (the rolling
limit); slots (>= P, 6 or 9 with rolling) [N, N, N m], pair (i, nbr[i, k]) at start[i] + k,
used for the pairs across chunks only; blocks (T, FIELDS*BLOCK) float64, block_ids (T,
ID_ROWS*BLOCK) uint64 (i, j and the spring's index of each contact of a block, then the touching
pairs of the piece being swept), block_rows (T, 2*BLOCK) int64 (rows waiting for their slots):
scratch per chunk; out force, torque (N,3) [N, N m]. The (N,3) arrays and hist
must be C-contiguous: the kernels read them through flat views (kernels/layout.py).
"""

import math

import numpy as np
from numba import njit, prange

from .laws import (
    COLUMNS,
    D_N,
    D_T,
    HERTZ_MINDLIN,
    K_N,
    K_T,
    MU,
    MU_R,
    contact_response,
    reduced,
)
from .layout import U1, U2, U3, flat, prefetch_particle
from .neighbors import minimum_image
from .serial import positions, serial_kernel

# Rows of a block (module docstring). 64 contacts: the block's 48 rows (24 KB) stay in L1.
BLOCK = 64
# inputs: separation d = x_i - x_j and |d|^2; v_i - v_j, r_i w_i + r_j w_j at the half step (A, S)
# and predicted (P, Q); masses, radii; the spring (replaced by the new one)
B_D0, B_D1, B_D2, B_DIST2 = 0, 1, 2, 3
# a wall contact has its normal and overlap in these rows instead
B_N0, B_N1, B_N2, B_DELTA = 0, 1, 2, 3
B_A0, B_A1, B_A2, B_S0, B_S1, B_S2 = 4, 5, 6, 7, 8, 9
B_P0, B_P1, B_P2, B_Q0, B_Q1, B_Q2 = 10, 11, 12, 13, 14, 15
B_MI, B_RI, B_RJ = 16, 18, 19  # B_MI: the contact's reduced mass m* (row 17 unused)
B_H0, B_H1, B_H2 = 20, 21, 22
# with rolling resistance: w_i - w_j at the half step, the reduced moment of inertia I* (row 27
# unused)
B_W0, B_W1, B_W2, B_II = 23, 24, 25, 26
# with several materials: the pair's table row
B_ROW = 28  # B_ROW + column (K_N ... MU_R)
# outputs: force on i, n x F_t, rolling torque on i
B_E0, B_E1, B_E2, B_C0, B_C1, B_C2, B_M0, B_M1, B_M2 = 34, 35, 36, 37, 38, 39, 40, 41, 42
# the separations of a piece of BLOCK listed pairs being swept, by their place in the piece
# (touching_pairs): d and |d|^2
B_X0, B_X1, B_X2, B_XD2 = 43, 44, 45, 46
FIELDS = 47
# how many listed pairs ahead of the one being measured the sweep prefetches a partner's lines
# where asked (touching_pairs): about 46 rows of the settled bed, a few microseconds of the sweep
# against the hundred nanoseconds of a miss to memory (64 ahead saved less in the measurements
# of docs/performance.md, 320 and 640 as much)
PREFETCH_AHEAD = 160
# per contact, in a companion uint64 array: the row i, the partner j and its spring's index;
# then the places of the touching pairs of the piece being swept (touching_pairs)
ID_I, ID_J, ID_S, ID_K = 0, 1, 2, 3
ID_ROWS = 4
# a block's fill count starts from this (an int64, not the literal 0, which would make Numba
# compile the flush functions a second time for a literal count)
ZERO = np.int64(0)


@njit(cache=True, inline="always")
def to_block(buf, field, c, value):
    buf[np.uint64(field * BLOCK) + c] = value


@njit(cache=True, inline="always")
def from_block(buf, field, c):
    return buf[np.uint64(field * BLOCK) + c]


@njit(cache=True)
def pack_pairs(nbr, nbr_count, start, pair_row, pair_partner):
    """The listed pairs in the springs' order: pair s = start[i] + k is (i, nbr[i, k]), its row
    into pair_row[s] and its partner into pair_partner[s] (int32, at least start[-1] long)."""
    cap = nbr.shape[1]
    for i in range(nbr.shape[0]):
        for k in range(min(nbr_count[i], cap)):
            pair_row[start[i] + k] = i
            pair_partner[start[i] + k] = nbr[i, k]


@njit(cache=True, inline="always")
def _law(
    buf,
    c,
    n0,
    n1,
    n2,
    delta,
    root_m,
    r_eff,
    i_eff,
    kn,
    kt,
    dn,
    dt,
    mu,
    mu_r,
    law,
    rolling,
    spring_dt,
    step_dt,
):
    """The law of contact c of a block (laws.py contact_response), from its normal n (from the
    partner to i), overlap delta [m], sqrt of the reduced mass [kg^1/2], R* [m] and I* [kg m^2]
    (pairs and walls alike): reads the velocity and spring rows, writes the results and the new
    spring."""
    w0 = w1 = w2 = 0.0
    if rolling:
        w0 = buf[B_W0 * BLOCK + c]
        w1 = buf[B_W1 * BLOCK + c]
        w2 = buf[B_W2 * BLOCK + c]
    e0, e1, e2, c0, c1, c2, m0, m1, m2, x0, x1, x2 = contact_response(
        (n0, n1, n2), delta, root_m, r_eff, i_eff, (kn, kt, dn, dt, mu, mu_r), law, rolling, spring_dt,
        step_dt,
        (buf[B_A0 * BLOCK + c], buf[B_A1 * BLOCK + c], buf[B_A2 * BLOCK + c]),
        (buf[B_S0 * BLOCK + c], buf[B_S1 * BLOCK + c], buf[B_S2 * BLOCK + c]),
        (buf[B_P0 * BLOCK + c], buf[B_P1 * BLOCK + c], buf[B_P2 * BLOCK + c]),
        (buf[B_Q0 * BLOCK + c], buf[B_Q1 * BLOCK + c], buf[B_Q2 * BLOCK + c]),
        (buf[B_H0 * BLOCK + c], buf[B_H1 * BLOCK + c], buf[B_H2 * BLOCK + c]),
        (w0, w1, w2),
    )  # fmt: skip
    buf[B_H0 * BLOCK + c] = x0
    buf[B_H1 * BLOCK + c] = x1
    buf[B_H2 * BLOCK + c] = x2
    buf[B_E0 * BLOCK + c] = e0
    buf[B_E1 * BLOCK + c] = e1
    buf[B_E2 * BLOCK + c] = e2
    buf[B_C0 * BLOCK + c] = c0
    buf[B_C1 * BLOCK + c] = c1
    buf[B_C2 * BLOCK + c] = c2
    if rolling:
        buf[B_M0 * BLOCK + c] = m0
        buf[B_M1 * BLOCK + c] = m1
        buf[B_M2 * BLOCK + c] = m2


@njit(cache=True, inline="always")
def _pair_contact(buf, c, law, rolling, single, kn1, kt1, dn1, dt1, mu1, mur1, spring_dt, step_dt):
    """The law of pair contact c of a block; kn1 ... mur1: the table row when there is one
    material."""
    d0 = buf[B_D0 * BLOCK + c]
    d1 = buf[B_D1 * BLOCK + c]
    d2 = buf[B_D2 * BLOCK + c]
    ri = buf[B_RI * BLOCK + c]
    rj = buf[B_RJ * BLOCK + c]
    dist = math.sqrt(buf[B_DIST2 * BLOCK + c])
    inv = 1.0 / dist
    r_eff = 0.0
    if law == HERTZ_MINDLIN or rolling:
        r_eff = ri * rj / (ri + rj)
    i_eff = 0.0
    if rolling:
        i_eff = buf[B_II * BLOCK + c]
    kn = kn1
    kt = kt1
    dn = dn1
    dt = dt1
    mu = mu1
    mu_r = mur1
    if not single:
        kn = buf[(B_ROW + K_N) * BLOCK + c]
        kt = buf[(B_ROW + K_T) * BLOCK + c]
        dn = buf[(B_ROW + D_N) * BLOCK + c]
        dt = buf[(B_ROW + D_T) * BLOCK + c]
        mu = buf[(B_ROW + MU) * BLOCK + c]
        mu_r = buf[(B_ROW + MU_R) * BLOCK + c]
    _law(
        buf,
        c,
        d0 * inv,
        d1 * inv,
        d2 * inv,
        (ri + rj) - dist,
        math.sqrt(buf[B_MI * BLOCK + c]),  # sqrt of the reduced mass
        r_eff,
        i_eff,
        kn,
        kt,
        dn,
        dt,
        mu,
        mu_r,
        law,
        rolling,
        spring_dt,
        step_dt,
    )


@njit(cache=True, error_model="numpy")
def contact_law(buf, count, law, rolling, single, table, spring_dt, step_dt):
    """The law for the first `count` pair contacts of a block (module docstring): normal force,
    tangential spring with its Coulomb cap, rolling torque, written into the output rows; the
    spring rows are replaced by the new springs. With one material the table row is table[0, 0].
    One loop per setting of `rolling`, so that a loop computes no unused torque."""
    row = table[0, 0]
    kn1, kt1, dn1, dt1, mu1, mur1 = row[K_N], row[K_T], row[D_N], row[D_T], row[MU], row[MU_R]
    if rolling:
        for c in range(count):
            _pair_contact(buf, c, law, True, single, kn1, kt1, dn1, dt1, mu1, mur1, spring_dt, step_dt)
    else:
        for c in range(count):
            _pair_contact(buf, c, law, False, single, kn1, kt1, dn1, dt1, mu1, mur1, spring_dt, step_dt)


@njit(cache=True, inline="always")
def _wall_contact(buf, c, law, rolling, spring_dt, step_dt):
    """The law of wall contact c of a block: the wall is a body of infinite mass, radius and
    inertia (m* = m_i, R* = r_i, I* = I_i), its normal and the overlap in the rows of d and
    |d|^2, its table row always in the block (kernels/walls.py)."""
    _law(
        buf,
        c,
        buf[B_N0 * BLOCK + c],
        buf[B_N1 * BLOCK + c],
        buf[B_N2 * BLOCK + c],
        buf[B_DELTA * BLOCK + c],
        math.sqrt(buf[B_MI * BLOCK + c]),
        buf[B_RI * BLOCK + c],
        buf[B_II * BLOCK + c],
        buf[(B_ROW + K_N) * BLOCK + c],
        buf[(B_ROW + K_T) * BLOCK + c],
        buf[(B_ROW + D_N) * BLOCK + c],
        buf[(B_ROW + D_T) * BLOCK + c],
        buf[(B_ROW + MU) * BLOCK + c],
        buf[(B_ROW + MU_R) * BLOCK + c],
        law,
        rolling,
        spring_dt,
        step_dt,
    )


@njit(cache=True, error_model="numpy")
def wall_law(buf, count, law, rolling, spring_dt, step_dt):
    """contact_law for a block of wall contacts (kernels/walls.py fills it); one loop for both
    settings of rolling (the walls' contacts are few, and a second loop costs seconds of
    compilation)."""
    for c in range(count):
        _wall_contact(buf, c, law, rolling, spring_dt, step_dt)


@njit(cache=True, inline="always")
def box_axes(length, periodic):
    """(L_x, L_y, L_z, periodic_x, periodic_y, periodic_z) as scalars, read once per kernel:
    the sweeps store into arrays, so the compiler would reload them from memory at every pair."""
    return length[0], length[1], length[2], periodic[0] != 0, periodic[1] != 0, periodic[2] != 0


@njit(cache=True, inline="always")
def separation(pos, hist, s, j, x0, x1, x2, ri, rj, box):
    """(touching, d = x_i - x_j (3 values), |d|^2) of the pair (i at x, j) whose spring is
    hist[s]; clears the spring of a pair that does not touch (hist has no rows when no contact has
    friction: nothing to clear). box: box_axes(length, periodic)."""
    j3 = U3 * j
    s3 = U3 * s
    d0 = minimum_image(x0 - pos[j3], box[0], box[3])
    d1 = minimum_image(x1 - pos[j3 + U1], box[1], box[4])
    d2 = minimum_image(x2 - pos[j3 + U2], box[2], box[5])
    dist2 = d0 * d0 + d1 * d1 + d2 * d2
    reach = ri + rj
    if dist2 >= reach * reach:
        if hist.shape[0] > 0 and (hist[s3] != 0.0 or hist[s3 + U1] != 0.0 or hist[s3 + U2] != 0.0):
            hist[s3] = 0.0  # the pair has separated: its spring is gone
            hist[s3 + U1] = 0.0
            hist[s3 + U2] = 0.0
        return False, d0, d1, d2, dist2
    return True, d0, d1, d2, dist2


@njit(cache=True, inline="always")
def touching_pairs(
    pos, radius, pair_row, pair_partner, first, last, end, box, partner, warm, hist, bits, buf, ids
):  # fmt: skip
    """The places p (pair first + p, first <= pair < last, at most BLOCK of them) of the listed
    pairs that touch and whose partner lies before `end` (the chunk's: the others are computed
    apart, cross_chunk_pairs), in order into row ID_K of ids; returns their number. Each pair's
    separation's d = x_i - x_j and |d|^2 go into the block's rows B_X0 ... B_XD2 at p, and the
    spring of a pair of the chunk that does not touch is cleared where it is set (as separation
    does): through `bits`, the springs' bits, ANDed with a mask of ones or zeros rather than
    stored under a branch, which would be mispredicted as often as the pairs' test. `partner`:
    the velocity arrays, inverse masses, forces and torques that gather and the flush read of a
    partner (with pos and radius, read here). Where `warm`, the lines of the partners of the
    piece PREFETCH_AHEAD listed pairs on are prefetched first: on a bed larger than the caches a
    row's partners one layer of the bed ahead come from memory, and the hints overlap those
    misses (the settled 100 000 bed on one thread stepped 1.13-1.22 x faster than with the
    partners' velocities loaded in the loop below, as before); on a bed inside the caches they
    only cost: physics/contact.py chooses."""
    vel, angvel, vel_pred, angvel_pred, inv_mass, force, torque = partner
    if warm:
        for pair in range(first + PREFETCH_AHEAD, min(last + PREFETCH_AHEAD, pair_partner.shape[0])):
            k = np.uint64(pair_partner[pair])
            prefetch_particle(k, (pos, vel, angvel, vel_pred, angvel_pred, force, torque), (inv_mass, radius))
    touching = np.uint64(0)
    for pair in range(first, last):
        p = np.uint64(pair - first)
        i = np.uint64(pair_row[pair])
        j = np.uint64(pair_partner[pair])
        i3 = U3 * i
        j3 = U3 * j
        d0 = minimum_image(pos[i3] - pos[j3], box[0], box[3])
        d1 = minimum_image(pos[i3 + U1] - pos[j3 + U1], box[1], box[4])
        d2 = minimum_image(pos[i3 + U2] - pos[j3 + U2], box[2], box[5])
        dist2 = d0 * d0 + d1 * d1 + d2 * d2
        reach = radius[i] + radius[j]
        to_block(buf, B_X0, p, d0)
        to_block(buf, B_X1, p, d1)
        to_block(buf, B_X2, p, d2)
        to_block(buf, B_XD2, p, dist2)
        apart = dist2 >= reach * reach
        inside = j < np.uint64(end)
        if hist.shape[0] > 0:
            s3 = U3 * np.uint64(pair)
            stale = apart & inside & ((hist[s3] != 0.0) | (hist[s3 + U1] != 0.0) | (hist[s3 + U2] != 0.0))
            keep = np.uint64(0) - np.uint64(not stale)  # all ones, or zeros (+0.0) to clear
            bits[s3] &= keep
            bits[s3 + U1] &= keep
            bits[s3 + U2] &= keep
        ids[np.uint64(ID_K * BLOCK) + touching] = p
        touching += np.uint64((not apart) & inside)
    return touching


@njit(cache=True, inline="always")
def gather(
    buf, ids, c, i, j, s, d0, d1, d2, dist2, ri, rj, vel, angvel, vel_pred, angvel_pred, inv_mass,
    inv_inertia, material, hist, table, single, rolling,
):  # fmt: skip
    """Copy the law's inputs of the touching pair (i, j = nbr[i, k]) into slot c of the block."""
    i3 = U3 * i
    j3 = U3 * j
    s3 = U3 * s
    ids[np.uint64(ID_I * BLOCK) + c] = i
    ids[np.uint64(ID_J * BLOCK) + c] = j
    ids[np.uint64(ID_S * BLOCK) + c] = s
    to_block(buf, B_D0, c, d0)
    to_block(buf, B_D1, c, d1)
    to_block(buf, B_D2, c, d2)
    to_block(buf, B_DIST2, c, dist2)
    to_block(buf, B_A0, c, vel[i3] - vel[j3])
    to_block(buf, B_A1, c, vel[i3 + U1] - vel[j3 + U1])
    to_block(buf, B_A2, c, vel[i3 + U2] - vel[j3 + U2])
    to_block(buf, B_S0, c, ri * angvel[i3] + rj * angvel[j3])
    to_block(buf, B_S1, c, ri * angvel[i3 + U1] + rj * angvel[j3 + U1])
    to_block(buf, B_S2, c, ri * angvel[i3 + U2] + rj * angvel[j3 + U2])
    to_block(buf, B_P0, c, vel_pred[i3] - vel_pred[j3])
    to_block(buf, B_P1, c, vel_pred[i3 + U1] - vel_pred[j3 + U1])
    to_block(buf, B_P2, c, vel_pred[i3 + U2] - vel_pred[j3 + U2])
    to_block(buf, B_Q0, c, ri * angvel_pred[i3] + rj * angvel_pred[j3])
    to_block(buf, B_Q1, c, ri * angvel_pred[i3 + U1] + rj * angvel_pred[j3 + U1])
    to_block(buf, B_Q2, c, ri * angvel_pred[i3 + U2] + rj * angvel_pred[j3 + U2])
    to_block(buf, B_MI, c, reduced(inv_mass[i], inv_mass[j]))
    to_block(buf, B_RI, c, ri)
    to_block(buf, B_RJ, c, rj)
    if hist.shape[0] > 0:
        to_block(buf, B_H0, c, hist[s3])
        to_block(buf, B_H1, c, hist[s3 + U1])
        to_block(buf, B_H2, c, hist[s3 + U2])
    else:  # frictionless: no springs
        to_block(buf, B_H0, c, 0.0)
        to_block(buf, B_H1, c, 0.0)
        to_block(buf, B_H2, c, 0.0)
    if rolling:
        to_block(buf, B_W0, c, angvel[i3] - angvel[j3])
        to_block(buf, B_W1, c, angvel[i3 + U1] - angvel[j3 + U1])
        to_block(buf, B_W2, c, angvel[i3 + U2] - angvel[j3 + U2])
        to_block(buf, B_II, c, reduced(inv_inertia[i], inv_inertia[j]))
    if not single:
        a = np.uint64(material[i])
        b = np.uint64(material[j])
        for col in range(COLUMNS):
            to_block(buf, B_ROW + col, c, table[a, b, col])


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


@njit(cache=True)
def _flush_to_slots(buf, ids, count, law, rolling, single, table, spring_dt, step_dt, hist, slots):
    """The law for the block's contacts (pairs across chunks), then each into its slot, at the
    index of its spring, and the new springs."""
    contact_law(buf, count, law, rolling, single, table, spring_dt, step_dt)
    for b in range(count):
        c = np.uint64(b)
        s = ids[np.uint64(ID_S * BLOCK) + c]
        s3 = U3 * s
        if hist.shape[0] > 0:
            hist[s3] = from_block(buf, B_H0, c)
            hist[s3 + U1] = from_block(buf, B_H1, c)
            hist[s3 + U2] = from_block(buf, B_H2, c)
        slots[s, 0] = from_block(buf, B_E0, c)
        slots[s, 1] = from_block(buf, B_E1, c)
        slots[s, 2] = from_block(buf, B_E2, c)
        slots[s, 3] = from_block(buf, B_C0, c)
        slots[s, 4] = from_block(buf, B_C1, c)
        slots[s, 5] = from_block(buf, B_C2, c)
        if rolling:
            slots[s, 6] = from_block(buf, B_M0, c)
            slots[s, 7] = from_block(buf, B_M1, c)
            slots[s, 8] = from_block(buf, B_M2, c)


# its arrays are the particles', the list's, the slots and this kernel's scratch
# (physics/contact.py), none a view of another
@serial_kernel(distinct=True)
def cross_chunk_pairs_serial(
    pos,
    vel,
    angvel,
    vel_pred,
    angvel_pred,
    radius,
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
    length,
    periodic,
    spring_dt,
    step_dt,
    cross_rows,
    cross_bounds,
    slots,
    blocks,
    block_ids,
):
    """Every listed pair whose partner lies in a later chunk, into its slot s = start[i] + k
    (the index of its spring): slots[s, 0:3] the force on i, [3:6] n x F_t, [6:9] the rolling
    torque on i (with rolling); zero for a pair that does not touch. cross_rows (R,2) int64:
    each row holding such pairs and the end of its chunk; cross_bounds (T+1,) int64: piece c
    of those rows, cross_bounds[c] <= r < cross_bounds[c+1] (any cut gives the same slots),
    swept one after the other here and each on a thread of its own by cross_chunk_pairs."""
    pos, vel, angvel, hist = flat(pos), flat(vel), flat(angvel), flat(hist)
    vel_pred, angvel_pred = flat(vel_pred), flat(angvel_pred)
    cap = nbr.shape[1]
    single = table.shape[0] == 1
    box = box_axes(length, periodic)
    for c in range(cross_bounds.shape[0] - 1):
        buf = blocks[c]
        ids = block_ids[c]
        filled = ZERO
        for r in range(cross_bounds[c], cross_bounds[c + 1]):
            i = np.uint64(cross_rows[r, 0])
            i3 = U3 * i
            count = min(nbr_count[i], cap)
            first = cross_start(nbr, i, count, cross_rows[r, 1])
            ri = radius[i]
            x0 = pos[i3]
            x1 = pos[i3 + U1]
            x2 = pos[i3 + U2]
            for slot in range(first, count):
                k = np.uint64(slot)
                j = np.uint64(nbr[i, k])
                rj = radius[j]
                s = np.uint64(start[i] + slot)
                touching, d0, d1, d2, dist2 = separation(pos, hist, s, j, x0, x1, x2, ri, rj, box)
                if not touching:
                    for col in range(slots.shape[1]):
                        slots[s, col] = 0.0
                    continue
                if filled == BLOCK:
                    _flush_to_slots(
                        buf, ids, filled, law, rolling, single, table, spring_dt, step_dt, hist, slots
                    )
                    filled = ZERO
                gather(
                    buf, ids, np.uint64(filled), i, j, s, d0, d1, d2, dist2, ri, rj,
                    vel, angvel, vel_pred, angvel_pred, inv_mass, inv_inertia, material, hist, table, single,
                    rolling,
                )  # fmt: skip
                filled += 1
        _flush_to_slots(buf, ids, filled, law, rolling, single, table, spring_dt, step_dt, hist, slots)


# where cross_chunk_pairs takes the pieces of its rows and a piece's scratch
CROSS_BOUNDS, CROSS_SLOTS, CROSS_BLOCKS, CROSS_BLOCK_IDS = positions(
    cross_chunk_pairs_serial, "cross_bounds", "slots", "blocks", "block_ids"
)


@njit(cache=True)
def one_cross_piece(cross, c):
    """cross_chunk_pairs's arguments `cross` for its piece c alone (its bounds and its rows of
    the scratch; the slots every piece's)."""
    bounds, blocks, ids = cross[CROSS_BOUNDS], cross[CROSS_BLOCKS], cross[CROSS_BLOCK_IDS]
    return cross[:CROSS_BOUNDS] + (bounds[c : c + 2], cross[CROSS_SLOTS], blocks[c : c + 1], ids[c : c + 1])


@njit(cache=True, parallel=True)
def cross_chunk_pairs(
    pos, vel, angvel, vel_pred, angvel_pred, radius, inv_mass, inv_inertia, material, nbr, nbr_count,
    start, hist, table, law, rolling, length, periodic, spring_dt, step_dt, cross_rows, cross_bounds,
    slots, blocks, block_ids,
):  # fmt: skip
    """cross_chunk_pairs_serial on several threads, piece c of the rows on one of them (each
    pair's slot is its own: any cut gives the same slots)."""
    cross = (
        pos, vel, angvel, vel_pred, angvel_pred, radius, inv_mass, inv_inertia, material, nbr, nbr_count,
        start, hist, table, law, rolling, length, periodic, spring_dt, step_dt, cross_rows, cross_bounds,
        slots, blocks, block_ids,
    )  # fmt: skip
    for c in prange(cross_bounds.shape[0] - 1):
        cross_chunk_pairs_serial(*one_cross_piece(cross, c))


@njit(cache=True)
def _flush_to_forces(
    buf, ids, count, waiting, rows, law, rolling, single, table, spring_dt, step_dt, radius, nbr_count,
    start, hist, cap, slots, force, torque,
):  # fmt: skip
    """The law for the block's contacts, then apply them in order (the force on j is the
    negative, its torque from r_j); then add to each of the `waiting` rows listed (rows whose
    pairs are all in, or before, this block) its pairs across chunks from their slots. Returns
    the emptied block's counts (contacts, waiting rows)."""
    contact_law(buf, count, law, rolling, single, table, spring_dt, step_dt)
    b = np.uint64(0)
    end = np.uint64(count)
    while b < end:
        i = ids[np.uint64(ID_I * BLOCK) + b]
        i3 = U3 * i
        ri = radius[i]
        f0 = force[i3]
        f1 = force[i3 + U1]
        f2 = force[i3 + U2]
        t0 = torque[i3]
        t1 = torque[i3 + U1]
        t2 = torque[i3 + U2]
        while b < end and ids[np.uint64(ID_I * BLOCK) + b] == i:
            j = ids[np.uint64(ID_J * BLOCK) + b]
            s = ids[np.uint64(ID_S * BLOCK) + b]
            j3 = U3 * j
            s3 = U3 * s
            if hist.shape[0] > 0:
                hist[s3] = from_block(buf, B_H0, b)
                hist[s3 + U1] = from_block(buf, B_H1, b)
                hist[s3 + U2] = from_block(buf, B_H2, b)
            e0 = from_block(buf, B_E0, b)
            e1 = from_block(buf, B_E1, b)
            e2 = from_block(buf, B_E2, b)
            c0 = from_block(buf, B_C0, b)
            c1 = from_block(buf, B_C1, b)
            c2 = from_block(buf, B_C2, b)
            f0 += e0
            f1 += e1
            f2 += e2
            t0 -= ri * c0
            t1 -= ri * c1
            t2 -= ri * c2
            rj = radius[j]
            force[j3] -= e0
            force[j3 + U1] -= e1
            force[j3 + U2] -= e2
            torque[j3] -= rj * c0
            torque[j3 + U1] -= rj * c1
            torque[j3 + U2] -= rj * c2
            if rolling:
                m0 = from_block(buf, B_M0, b)
                m1 = from_block(buf, B_M1, b)
                m2 = from_block(buf, B_M2, b)
                t0 += m0
                t1 += m1
                t2 += m2
                torque[j3] -= m0
                torque[j3 + U1] -= m1
                torque[j3 + U2] -= m2
            b += np.uint64(1)
        force[i3] = f0
        force[i3 + U1] = f1
        force[i3 + U2] = f2
        torque[i3] = t0
        torque[i3 + U1] = t1
        torque[i3 + U2] = t2
    for w in range(waiting):
        i = np.uint64(rows[w])
        i3 = U3 * i
        ri = radius[i]
        for slot in range(rows[BLOCK + w], min(nbr_count[i], cap)):
            s = np.uint64(start[i] + slot)
            force[i3] += slots[s, 0]
            force[i3 + U1] += slots[s, 1]
            force[i3 + U2] += slots[s, 2]
            torque[i3] -= ri * slots[s, 3]
            torque[i3 + U1] -= ri * slots[s, 4]
            torque[i3 + U2] -= ri * slots[s, 5]
            if rolling:
                torque[i3] += slots[s, 6]
                torque[i3 + U1] += slots[s, 7]
                torque[i3 + U2] += slots[s, 8]
    return ZERO, ZERO


# its arrays are the particles', the list's and this kernel's scratch (physics/contact.py),
# none a view of another
@serial_kernel(distinct=True)
def chunk_pair_forces_serial(
    pos,
    vel,
    angvel,
    vel_pred,
    angvel_pred,
    radius,
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
    length,
    periodic,
    spring_dt,
    step_dt,
    rev,
    rev_count,
    pair_row,
    pair_partner,
    warm,
    body_acc,
    mass,
    bounds,
    slots,
    blocks,
    block_ids,
    block_rows,
    force,
    torque,
):
    """Set force = m g + the sum of the pair forces and torque = the sum of the pair torques,
    chunk by chunk: first m g minus the pairs (j, i) with j in an earlier chunk (their slots,
    ascending j), then a sweep in ascending i applying the pairs inside the chunk to both
    members, block by block, and adding the row's pairs beyond the chunk from their slots
    (cross_chunk_pairs must have run). Each particle's terms come in ascending partner index
    (module docstring). The chunks one after the other: one thread's kernel, which
    chunk_pair_forces calls for each chunk on its thread (kernels/serial.py serial_kernel)."""
    pos, vel, angvel, hist = flat(pos), flat(vel), flat(angvel), flat(hist)
    bits = hist.view(np.uint64)
    vel_pred, angvel_pred = flat(vel_pred), flat(angvel_pred)
    # the first pass sets each row through the (N,3) arrays: flat there too, the sweep's
    # registers come out worse (callgrind, settled 10 000: 555 -> 533 instructions per particle)
    force_rows, torque_rows = force, torque
    force, torque = flat(force), flat(torque)
    cap = nbr.shape[1]
    partner = (vel, angvel, vel_pred, angvel_pred, inv_mass, force, torque)
    rcap = rev.shape[1]
    single = table.shape[0] == 1
    box = box_axes(length, periodic)
    for c in range(bounds.shape[0] - 1):
        begin = bounds[c]
        end = bounds[c + 1]
        buf = blocks[c]
        ids = block_ids[c]
        rows = block_rows[
            c
        ]  # rows waiting for their slots: [0, BLOCK) the row, [BLOCK, 2 BLOCK) its first slot
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
                if rev[i, m] >= start[begin]:
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
            force_rows[i, 0] = f0
            force_rows[i, 1] = f1
            force_rows[i, 2] = f2
            torque_rows[i, 0] = t0
            torque_rows[i, 1] = t1
            torque_rows[i, 2] = t2
        filled = ZERO
        waiting = ZERO
        row = begin  # the next row that may wait for its pairs beyond the chunk
        for first in range(start[begin], start[end], BLOCK):  # the chunk's pairs, a piece at a time
            last = min(first + BLOCK, start[end])
            touching = touching_pairs(
                pos, radius, pair_row, pair_partner, first, last, end, box, partner, warm, hist, bits, buf,
                ids,
            )  # fmt: skip
            for q in range(touching):
                p = ids[np.uint64(ID_K * BLOCK) + np.uint64(q)]
                s = np.uint64(first) + p
                i = np.uint64(pair_row[s])
                j = np.uint64(pair_partner[s])
                if filled == BLOCK:
                    filled, waiting = _flush_to_forces(
                        buf, ids, filled, waiting, rows, law, rolling, single, table, spring_dt, step_dt,
                        radius, nbr_count, start, hist, cap, slots, force, torque,
                    )  # fmt: skip
                gather(
                    buf, ids, np.uint64(filled), i, j, s,
                    from_block(buf, B_X0, p), from_block(buf, B_X1, p), from_block(buf, B_X2, p),
                    from_block(buf, B_XD2, p), radius[i], radius[j], vel, angvel, vel_pred, angvel_pred,
                    inv_mass, inv_inertia, material, hist, table, single, rolling,
                )  # fmt: skip
                filled += 1
            # the rows whose pairs are all swept now: those with pairs beyond the chunk wait for
            # their slots (none in the last chunk)
            while end < nbr.shape[0] and row < end and start[row + 1] <= last:
                i = np.uint64(row)
                count = min(nbr_count[i], cap)
                inner = cross_start(nbr, i, count, end)
                if inner < count:
                    if waiting == BLOCK:
                        filled, waiting = _flush_to_forces(
                            buf, ids, filled, waiting, rows, law, rolling, single, table, spring_dt, step_dt,
                            radius, nbr_count, start, hist, cap, slots, force, torque,
                        )  # fmt: skip
                    rows[waiting] = row
                    rows[BLOCK + waiting] = inner
                    waiting += 1
                row += 1
        _flush_to_forces(
            buf, ids, filled, waiting, rows, law, rolling, single, table, spring_dt, step_dt,
            radius, nbr_count, start, hist, cap, slots, force, torque,
        )  # fmt: skip


# where chunk_pair_forces takes the chunks' bounds, the slots and its scratch of a chunk each
BOUNDS, SLOTS, BLOCKS, BLOCK_IDS, BLOCK_ROWS = positions(
    chunk_pair_forces_serial, "bounds", "slots", "blocks", "block_ids", "block_rows"
)
AFTER_SCRATCH = BLOCK_ROWS + 1


@njit(cache=True, parallel=True)
def chunk_pair_forces(
    pos, vel, angvel, vel_pred, angvel_pred, radius, inv_mass, inv_inertia, material, nbr, nbr_count,
    start, hist, table, law, rolling, length, periodic, spring_dt, step_dt, rev, rev_count, pair_row,
    pair_partner, warm, body_acc, mass, bounds, slots, blocks, block_ids, block_rows, force, torque,
):  # fmt: skip
    """chunk_pair_forces_serial's sweep on several threads, chunk c on one of them: each chunk's
    rows and scratch are its own, and the slots it reads were filled by cross_chunk_pairs
    before."""
    pairs = (
        pos, vel, angvel, vel_pred, angvel_pred, radius, inv_mass, inv_inertia, material, nbr, nbr_count,
        start, hist, table, law, rolling, length, periodic, spring_dt, step_dt, rev, rev_count, pair_row,
        pair_partner, warm, body_acc, mass, bounds, slots, blocks, block_ids, block_rows, force, torque,
    )  # fmt: skip
    for c in prange(bounds.shape[0] - 1):
        chunk_pair_forces_serial(*one_chunk(pairs, c))


@njit(cache=True)
def one_chunk(pairs, c):
    """chunk_pair_forces's arguments `pairs` for its chunk c alone (its bounds and its rows of the
    scratch; the slots every chunk's), which chunk_pair_forces_serial sweeps on its own
    (chunk_pair_forces, kernels/steps.py chunk_steps_end)."""
    bounds, blocks, ids, rows = pairs[BOUNDS], pairs[BLOCKS], pairs[BLOCK_IDS], pairs[BLOCK_ROWS]
    chunk = (bounds[c : c + 2], pairs[SLOTS], blocks[c : c + 1], ids[c : c + 1], rows[c : c + 1])
    return pairs[:BOUNDS] + chunk + pairs[AFTER_SCRATCH:]
