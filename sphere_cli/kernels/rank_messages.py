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

mpi: (allreduce, irecv, isend, waitall, clock_gettime, the communicator, MPI_DOUBLE, MPI_MAX and
the monotonic clock's id); mail (rank_calls.ghost_mail): the ranks sent to and their rows (a
rank m's are local[start[m]:start[m + 1]], its box the same rows of `out`), the same for the
ranks received from, the requests and statuses of one step's messages; clock (2,) int64 scratch.
"""

import numpy as np
from numba import njit

from .motion import kick, kick_drift, kick_drift_serial, kick_serial
from .neighbors import rows_in, rows_out
from .serial import serial_twin
from .steps import contacts, contacts_serial

TAG = 1  # the ghosts' forces (the Python exchange's tag: the same messages)


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
def rank_dem_steps(steps, threshold2, drift, cross, pairs, walls, kicks, mpi, mail, scratch):
    """Up to `steps` steps of a rank's part (kernels/steps.py dem_steps, fixed walls): returns
    (the complete steps taken, the last squared displacement over every rank, whether a drift
    made the list stale (the caller builds it and ends that step), the seconds in the forces,
    MPI's first error code). scratch: (2,) float64, (2,) int64: the reduction's and the clock's."""
    moved, clock = scratch
    mine, largest = moved[:1], moved[1:]
    busy = 0.0
    force, torque = kicks[2], kicks[3]
    for done in range(steps):
        mine[0] = kick_drift(*drift)
        code = largest_everywhere(mpi, mine, largest)
        if code != 0:
            return done, largest[0], False, busy, code
        if largest[0] > threshold2:
            return done, largest[0], True, busy, 0
        started = seconds(mpi, clock)
        contacts(cross, pairs, walls)
        busy += seconds(mpi, clock) - started
        code = send_ghost_forces(force, torque, mpi, mail)
        if code != 0:
            return done, largest[0], False, busy, code
        kick(*kicks)
    return steps, largest[0], False, busy, 0


# one thread and a small part: the loop without parallel regions (kernels/serial.py)
rank_dem_steps_serial = serial_twin(
    rank_dem_steps, kick_drift=kick_drift_serial, kick=kick_serial, contacts=contacts_serial
)
