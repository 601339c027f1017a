"""Velocity Verlet (kick-drift-kick) for translation and rotation of spheres.

x_{n+1} = x_n + dt (v_n + dt/2 a_n);  v_{n+1} = v_n + dt/2 (a_n + a_{n+1}).
Second order for conservative forces; a velocity-dependent force sees the half-step velocity
(as in LAMMPS). Spheres have isotropic inertia, so w is advanced like v and no orientation
is tracked.

Arguments: pos, vel, angvel, force, torque (N,3) [m, m/s, rad/s, N, N m];
inv_mass, inv_inertia (N,) [1/kg, 1/(kg m^2)], zero for a particle that does not move;
lower, length (3,) [m]; periodic (3,) uint8; dt [s]; ref_pos (N,3) [m] the positions at the
last build of the neighbour list (kernels/neighbors.py). The (N,3) arrays must be C-contiguous:
the kernels read them through flat views (kernels/layout.py).
"""

import math

import numpy as np
from numba import njit, prange

from .layout import U3, flat
from .neighbors import minimum_image
from .serial import positions, serial_twin

# the least particles of a run of kick_drift's region: its loops long enough to vectorise, and
# enough runs for the threads to share them evenly (a thread's share rounded to a run: 2.5 %
# of 10 000 particles on two threads)
KICK_RUN = 256


@njit(cache=True, inline="always")
def half_kick(v, w, f, t, inv_mass, inv_inertia, half, u):
    """v += dt/2 F/m and w += dt/2 T/I for particle u (unsigned) of the flat views."""
    for a in range(3):
        m = U3 * u + np.uint64(a)
        v[m] += half * f[m] * inv_mass[u]
        w[m] += half * t[m] * inv_inertia[u]


@njit(cache=True, parallel=True)
def kick_drift(
    pos,
    vel,
    angvel,
    force,
    torque,
    inv_mass,
    inv_inertia,
    lower,
    length,
    periodic,
    dt,
    vel_pred,
    angvel_pred,
    ref_pos,
    kick_first,
):
    """Half kick with the old forces, full drift, wrap into the periodic box; also the
    prediction v_n + dt a_n of v_{n+1} that the dashpots use (vel_pred, angvel_pred). Returns
    the largest squared displacement since the neighbour list was built (minimum image) [m^2],
    measured here while the positions are at hand rather than in a pass of their own; a max
    reduction is exact in any order, so it does not depend on the threads. One parallel region
    over runs of KICK_RUN particles or more, two loops in each run: the kick vectorises, the
    drift with its reduction does not, and together they would not either. (Each region wakes
    the threads where they sleep between regions, OMP_WAIT_POLICY=PASSIVE: about 45 us; two
    regions took 106-110 us a call at 10 000 on two threads, one 63-76 us.) With `kick_first`
    the last step's second half kick (`kick`) comes first, in the same loop: bitwise the two
    kernels one after the other, in one pass over the particles instead of two (at 100 000,
    beyond the cache, 10.6 -> 7.2 ns a particle on one thread) and one parallel region."""
    half = 0.5 * dt
    v, w, f, t = flat(vel), flat(angvel), flat(force), flat(torque)
    v_pred, w_pred = flat(vel_pred), flat(angvel_pred)
    x, x_ref = flat(pos), flat(ref_pos)
    n = pos.shape[0]
    runs = max(n // KICK_RUN, 1)
    worst = 0.0
    for r in prange(runs):
        first, last = np.uint64(r * n // runs), np.uint64((r + 1) * n // runs)
        for u in range(first, last):  # unsigned: no wraparound code in the indexing
            if kick_first:
                half_kick(v, w, f, t, inv_mass, inv_inertia, half, u)
            half_kick(v, w, f, t, inv_mass, inv_inertia, half, u)
            for a in range(3):
                m = U3 * u + np.uint64(a)
                v_pred[m] = v[m] + half * f[m] * inv_mass[u]
                w_pred[m] = w[m] + half * t[m] * inv_inertia[u]
        largest = 0.0
        for u in range(first, last):
            moved2 = 0.0
            for a in range(3):
                m = U3 * u + np.uint64(a)
                y = x[m] + dt * v[m]
                if periodic[a]:
                    if y >= lower[a] + length[a]:
                        y -= length[a]
                    elif y < lower[a]:
                        y += length[a]
                x[m] = y
                d = minimum_image(y - x_ref[m], length[a], periodic[a])
                moved2 += d * d
            largest = max(largest, moved2)
        worst = max(worst, largest)
    return worst


@njit(cache=True, parallel=True)
def kick(vel, angvel, force, torque, inv_mass, inv_inertia, dt):
    """Second half kick with the new forces."""
    half = 0.5 * dt
    v, w, f, t = flat(vel), flat(angvel), flat(force), flat(torque)
    for i in prange(vel.shape[0]):
        half_kick(v, w, f, t, inv_mass, inv_inertia, half, np.uint64(i))


@njit(cache=True, inline="always")
def unstable_reason(pos, vel, angvel, radius, lower, upper, periodic, dt, i):
    """Why particle i has gone bad: 1 = not finite, 2 = moves more than half its radius in one
    step (contacts would be missed), 3 = has left the box on a non-periodic axis; 0 if it has
    not (also the GPU's check, kernels/cuda_dem.py)."""
    speed2 = 0.0
    for a in range(3):
        if not (math.isfinite(pos[i, a]) and math.isfinite(vel[i, a]) and math.isfinite(angvel[i, a])):
            return 1
        speed2 += vel[i, a] * vel[i, a]
    if speed2 * dt * dt > 0.25 * radius[i] * radius[i]:
        return 2
    for a in range(3):
        if not periodic[a] and (pos[i, a] < lower[a] - radius[i] or pos[i, a] > upper[a] + radius[i]):
            return 3
    return 0


@njit(cache=True)
def first_unstable(pos, vel, angvel, radius, lower, upper, periodic, dt):
    """(index, reason) of the first particle that has gone bad (unstable_reason); (-1, 0) if
    none."""
    for i in range(pos.shape[0]):
        reason = unstable_reason(pos, vel, angvel, radius, lower, upper, periodic, dt, i)
        if reason:
            return i, reason
    return -1, 0


# one thread: the same kernels without parallel regions (kernels/serial.py); their array
# arguments are the particles' own arrays, never views of one another
# one thread: one run of every particle, the kick's loop over all of them before the drift's
kick_drift_serial = serial_twin(kick_drift, distinct=True, KICK_RUN=np.iinfo(np.int64).max)
kick_serial = serial_twin(kick, distinct=True)


# where kick_drift takes the box (lower, length, periodic) and dt, between its particle arrays
LOWER, VEL_PRED = positions(kick_drift, "lower", "vel_pred")


@njit(cache=True)
def particles_of(drift, first, last):
    """kick_drift's arguments `drift` for the particles first .. last - 1 alone (views of their
    rows; the box and the step as they are)."""
    pos, vel, angvel, force, torque, inv_mass, inv_inertia = drift[:LOWER]
    vel_pred, angvel_pred, ref_pos = drift[VEL_PRED:]
    return (
        (pos[first:last], vel[first:last], angvel[first:last], force[first:last], torque[first:last])
        + (inv_mass[first:last], inv_inertia[first:last])
        + drift[LOWER:VEL_PRED]
        + (vel_pred[first:last], angvel_pred[first:last], ref_pos[first:last])
    )
