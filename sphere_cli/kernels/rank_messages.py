"""A rank's DEM steps in one compiled call, its messages sent from inside (physics/rank_steps.py).

The one-rank loop of kernels/steps.py with what a rank adds to each step: the largest squared
displacement reduced over every rank (the list build's decision), and the forces and torques
of its own particles that are ghosts elsewhere sent to those ranks (their owners' sums). The
messages are the MPI library's own functions, called through addresses passed in as arguments
(`mpi`, made by physics/rank_calls.py), so the compiled loop is cached like every kernel: a
loop calling functions found at import (numba-mpi's ctypes pointers) is compiled again on every
rank of every run. The kernels, the arguments and their order are the Python loop's
(RankSteps._steps), so the results are bitwise the same; what is saved is the interpreter's
share of a rank's step.

Moving walls (`motion`, as kernels/steps.py dem_steps takes it but for the walls' totals) are
stepped on every rank alike; the particles' force on them is summed as one rank sums it: each
rank's rows of particles pushing a wall and of glued spheres gathered to every rank (MPI_Allgather
of the counts, MPI_Allgatherv of the rows, as RankSteps._gather_rows sends them), put in global
order and summed in the tree of kernels/walls.py (rank_wall_totals).

mpi: (allreduce, irecv, isend, waitall, clock_gettime, the communicator, MPI_DOUBLE, MPI_MAX,
the monotonic clock's id, allgather, allgatherv, MPI_INT64_T); mail (rank_calls.ghost_mail): the
ranks sent to and their rows (a rank m's are local[start[m]:start[m + 1]], its box the same rows
of `out`), the same for the ranks received from, the requests and statuses of one step's
messages; clock (2,) int64 scratch.
"""

import numpy as np
from numba import njit

from .motion import kick, kick_drift, kick_drift_serial, kick_serial
from .neighbors import rows_in, rows_out
from .serial import serial_twin
from .steps import contacts, contacts_serial, walls_moved
from .walls import finish_wall_totals, sparse_particle_pushes, wall_areas, wall_kick, wall_kick_drift

TAG = 1  # the ghosts' forces (the Python exchange's tag: the same messages)
GLUE = 5  # a glued sphere's row: its place in the lead's list, its force (3), its mass


@njit(cache=True)
def seconds(mpi, clock):
    """The monotonic clock [s] (for the measured work of rank_balance = "time")."""
    mpi[4](mpi[8], clock.ctypes.data)
    return clock[0] + 1e-9 * clock[1]


@njit(cache=True)
def largest_everywhere(mpi, mine, largest):
    """Allreduce MAX of mine (1,) into largest (1,); returns MPI's error code."""
    return mpi[0](mine.ctypes.data, largest.ctypes.data, np.int32(1), mpi[6], mpi[7], mpi[5])


@njit(cache=True)
def _post(call, box, rank, mpi, request):
    """MPI_Irecv or MPI_Isend (call) of the doubles of box from or to rank, into request[0]."""
    return call(box.ctypes.data, np.int32(box.size), mpi[6], rank, np.int32(TAG), mpi[5], request.ctypes.data)


@njit(cache=True)
def send_ghost_forces(force, torque, mpi, mail):
    """Each rank's rows of force and torque (3 + 3 doubles) to it, and those of the ghosts this
    rank holds from their owners; returns MPI's first error code (0: none)."""
    to, to_start, to_local, out, come, come_start, come_local, into, requests, statuses = mail
    messages = 0
    for m in range(come.shape[0]):
        box = into[come_start[m] : come_start[m + 1]]
        code = _post(mpi[1], box, come[m], mpi, requests[messages:])
        if code != 0:
            return code
        messages += 1
    for m in range(to.shape[0]):
        local = to_local[to_start[m] : to_start[m + 1]]
        box = out[to_start[m] : to_start[m + 1]]
        rows_out(force, local, box, 0)
        rows_out(torque, local, box, 3)
        code = _post(mpi[2], box, to[m], mpi, requests[messages:])
        if code != 0:
            return code
        messages += 1
    code = mpi[3](np.int32(messages), requests.ctypes.data, statuses.ctypes.data)
    if code != 0:
        return code
    for m in range(come.shape[0]):
        local = come_local[come_start[m] : come_start[m + 1]]
        box = into[come_start[m] : come_start[m + 1]]
        rows_in(box, local, force, 0)
        rows_in(box, local, torque, 3)
    return 0


@njit(cache=True)
def _pushes(pforce, record, i):
    """True if particle i has a force on a wall whose total is recorded."""
    for w in range(record.shape[0]):
        if record[w]:
            for b in range(3):
                if pforce[i, w, b] != 0.0:
                    return True
    return False


@njit(cache=True)
def _own_wall_rows(own, gid, pforce, record, glued, glued_order, force, mass, rows):
    """This rank's rows for the walls' totals into rows, flat: [global index, pforce (W x 3)] of
    each particle of `own` (its own particles near the walls, ascending) pushing a recorded wall,
    then [its place in the lead's list, force (3), mass] of each own glued sphere (glued: local
    indices)."""
    width = 1 + 3 * record.shape[0]
    r = 0
    for i in own:
        if _pushes(pforce, record, i):
            rows[r] = gid[i]
            for w in range(record.shape[0]):
                for b in range(3):
                    rows[r + 1 + 3 * w + b] = pforce[i, w, b]
            r += width
    for k in range(glued.shape[0]):
        i = glued[k]
        rows[r] = glued_order[k]
        for b in range(3):
            rows[r + 1 + b] = force[i, b]
        rows[r + 4] = mass[i]
        r += GLUE


@njit(cache=True)
def rank_wall_totals(
    mpi, own, gid, pforce, record, glued, glued_order, force, mass, attached_wall, count, psum, total,
    body_acc, fluid_force, wall_force, gather,
):  # fmt: skip
    """Collective: wall_force as one rank's wall_totals makes it (kernels/walls.py), from every
    rank's own particles pushing a wall (own: those near the walls, the only ones whose pforce
    may not be zero) and own glued spheres, gathered and put in global order: the pushes summed
    by sparse_particle_pushes (psum, total its scratch; count the scene's particles), the glued
    spheres in the lead's order (attached_wall: the lead's wall of each).
    gather: (2,) int64, (ranks, 2) int64, (ranks,) int32 twice: scratch. Returns MPI's error code."""
    counts, every, sizes, starts = gather
    walls = record.shape[0]
    width = 1 + 3 * walls
    counts[0] = 0
    for i in own:
        if _pushes(pforce, record, i):
            counts[0] += 1
    counts[1] = glued.shape[0]
    code = mpi[9](counts.ctypes.data, np.int32(2), mpi[11], every.ctypes.data, np.int32(2), mpi[11], mpi[5])
    if code != 0:
        return code
    arriving = 0
    for rank in range(every.shape[0]):
        sizes[rank] = every[rank, 0] * width + every[rank, 1] * GLUE
        starts[rank] = arriving
        arriving += sizes[rank]
    # one buffer, this rank's rows then every rank's: MPI reads and writes it by address, and
    # Numba keeps an array only up to its last use in the code (here arrived, a view of it)
    mine = counts[0] * width + counts[1] * GLUE
    buffer = np.empty(mine + arriving)
    _own_wall_rows(own, gid, pforce, record, glued, glued_order, force, mass, buffer)
    code = mpi[10](
        buffer.ctypes.data, np.int32(mine), mpi[6], buffer[mine:].ctypes.data, sizes.ctypes.data,
        starts.ctypes.data, mpi[6], mpi[5],
    )  # fmt: skip
    if code != 0:
        return code
    arrived = buffer[mine:]
    index, index_at = np.empty(every[:, 0].sum(), np.int64), np.empty(every[:, 0].sum(), np.int64)
    order, order_at = np.empty(every[:, 1].sum(), np.int64), np.empty(every[:, 1].sum(), np.int64)
    p = g = 0
    for rank in range(every.shape[0]):
        first = starts[rank]
        for _ in range(every[rank, 0]):
            index[p], index_at[p] = np.int64(arrived[first]), first
            first += width
            p += 1
        for _ in range(every[rank, 1]):
            order[g], order_at[g] = np.int64(arrived[first]), first
            first += GLUE
            g += 1
    pushes = np.empty((index.size, walls, 3))  # in the order they arrived
    for q in range(index.size):
        for w in range(walls):
            for b in range(3):
                pushes[q, w, b] = arrived[index_at[q] + 1 + 3 * w + b]
    by_index = np.argsort(index, kind="mergesort")
    sparse_particle_pushes(index[by_index], pushes, by_index, count, record, psum, total)
    by_order = np.argsort(order, kind="mergesort")
    glued_total, glued_mass = np.empty((order.size, 3)), np.empty(order.size)
    for q in range(order.size):
        at = order_at[by_order[q]]
        for b in range(3):
            glued_total[q, b] = arrived[at + 1 + b]
        glued_mass[q] = arrived[at + 4]
    finish_wall_totals(
        total, record, np.arange(order.size), attached_wall[order[by_order]], glued_total, glued_mass,
        body_acc, fluid_force, wall_force,
    )  # fmt: skip
    return 0


@njit(cache=True)
def rank_dem_steps(steps, step, threshold2, drift, cross, pairs, walls, kicks, motion, mpi, mail, scratch):
    """Up to `steps` steps of a rank's part from the clock's `step` (kernels/steps.py dem_steps):
    returns (the complete steps taken, the last squared displacement over every rank, whether a
    drift made the list stale or a wall left the reach of the near-wall list (the caller ends
    that step), the seconds in the forces, MPI's first error code). motion: None where no wall
    moves, else dem_steps's with rank_wall_totals's arguments but mpi in place of
    listed_wall_totals's, and without the clock's step (the arguments outlive a call: the step
    comes with each). scratch: (2,) float64, (2,) int64: the reduction's and the clock's."""
    moved, clock = scratch
    mine, largest = moved[:1], moved[1:]
    busy = 0.0
    force, torque = kicks[2], kicks[3]
    for done in range(steps):
        if motion is not None:
            wall_kick_drift(*motion[0])
        mine[0] = kick_drift(*drift)
        code = largest_everywhere(mpi, mine, largest)
        if code != 0:
            return done, largest[0], False, busy, code
        if largest[0] > threshold2:
            return done, largest[0], True, busy, 0
        if motion is not None and walls_moved(motion[0][4], motion[4], motion[5]):
            return done, largest[0], True, busy, 0
        started = seconds(mpi, clock)
        contacts(cross, pairs, walls)
        busy += seconds(mpi, clock) - started
        code = send_ghost_forces(force, torque, mpi, mail)
        if code != 0:
            return done, largest[0], False, busy, code
        if motion is not None:
            wall_areas(*motion[1])
            code = rank_wall_totals(mpi, *motion[2])
            if code != 0:
                return done, largest[0], False, busy, code
            wall_kick(*motion[3], (step + done + 1) * motion[6], motion[6])
        kick(*kicks)
    return steps, largest[0], False, busy, 0


# one thread and a small part: the loop without parallel regions (kernels/serial.py)
rank_dem_steps_serial = serial_twin(
    rank_dem_steps, kick_drift=kick_drift_serial, kick=kick_serial, contacts=contacts_serial
)
