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

A 1D VANS fluid's force on the particles (`fluid`: kernels/fluid/profile_forces.py
profile_forces's arguments, as the one-rank loop kernels/steps.py dem_steps takes them, called
as `fluid_force` by the fluid's variant of this loop, rank_vans1d_steps there) comes after
the contacts, where the forces hooks put it; it reads only the particle's own arrays and the
fluid's profiles, the same on every rank, so its ghosts' forces need nothing more than the
contacts' (their owners' sums overwrite them). None: no fluid.

Moving walls (`motion`, as kernels/steps.py dem_steps takes it but for the walls' totals) are
stepped on every rank alike; the particles' force on them is summed exactly (kernels/walls.py):
each rank adds its own particles' pushes and its own glued spheres' forces into the words of the
sums, and MPI_Allreduce adds those words over the ranks (rank_wall_totals): one rank's total,
bitwise, from a message of a fixed size (W x 3 x WORDS int64) whatever the particles' number.

The Navier-Stokes drag's loop, its kick in place of the particles' (kernels/fluid/drag.py
rank_drag_steps), sends each ghost's other forces with its force and torque, and, with the
self-induced velocity subtracted, the (cell, drag coefficient) rows its cells' sums take from
other ranks, with send_ghost_forces below (rank_cell_coefficients there).

mpi: (the addresses of MPI_Allreduce, MPI_Irecv, MPI_Isend, MPI_Waitall and clock_gettime, called
by kernels/c_calls.py call_c; the communicator, MPI_DOUBLE, MPI_MAX, the monotonic clock's id,
MPI_INT64_T, MPI_SUM); mail (rank_calls.ghost_mail): the
ranks sent to and their rows (a rank m's are local[start[m]:start[m + 1]], its box the same rows
of `out`), the same for the ranks received from, the requests and statuses of one step's
messages; clock (2,) int64 scratch.
"""

import numpy as np
from numba import njit

from .c_calls import call_c
from .motion import kick, kick_drift, kick_drift_serial, kick_serial
from .neighbors import rows_in, rows_out
from .observe.energy_budget import accumulate_budget, accumulate_budget_serial, keep_half_step
from .serial import serial_twin
from .steps import contacts, contacts_serial, fluid_force, walls_moved
from .walls import (
    add_glued,
    add_pushes,
    clear_sums,
    finish_wall_totals,
    wall_areas,
    wall_kick,
    wall_kick_drift,
)

# the tag of send_ghost_forces's messages and of the Python exchange's (the same messages): the
# ghosts' forces, and the Navier-Stokes drag's coefficient rows after them in a step (each
# exchange ends in MPI_Waitall before the next begins, so MPI's order per sender matches them)
TAG = 1


@njit(cache=True)
def seconds(mpi, clock):
    """The monotonic clock [s] (for the measured work of rank_balance = "time")."""
    call_c(mpi[4], (mpi[8], clock.ctypes.data))
    return clock[0] + 1e-9 * clock[1]


@njit(cache=True)
def largest_everywhere(mpi, mine, largest):
    """Allreduce MAX of mine (1,) into largest (1,); returns MPI's error code."""
    return call_c(mpi[0], (mine.ctypes.data, largest.ctypes.data, np.int32(1), mpi[6], mpi[7], mpi[5]))


@njit(cache=True)
def drift_everywhere(drift, mpi, mine, largest, kick_first):
    """The step's kick-drift of this rank's particles (kick_first: the last step's kick with
    it), and the largest squared displacement over every rank into largest (1,) (mine (1,)
    scratch); returns MPI's error code."""
    mine[0] = kick_drift(*drift, kick_first)
    return largest_everywhere(mpi, mine, largest)


@njit(cache=True)
def rank_drift(motion, drift, mpi, mine, largest, threshold2, kick_first):
    """The start of a rank loop's step: the walls' kick-drift (motion: rank_dem_steps's, None
    where no wall moves), the particles' (drift_everywhere), and whether the step must end in
    Python: a particle on any rank beyond half the skin, or a wall beyond the reach of its
    near-wall list. Returns (MPI's error code, that)."""
    if motion is not None:
        wall_kick_drift(*motion[0])
    code = drift_everywhere(drift, mpi, mine, largest, kick_first)
    if code != 0:
        return code, False
    if largest[0] > threshold2:
        return 0, True
    if motion is not None and walls_moved(motion[0][4], motion[4], motion[5]):
        return 0, True
    return 0, False


@njit(cache=True)
def _post(call, box, rank, mpi, request):
    """MPI_Irecv or MPI_Isend (call) of the doubles of box from or to rank, into request[0]."""
    return call_c(
        call, (box.ctypes.data, np.int32(box.size), mpi[6], rank, np.int32(TAG), mpi[5], request.ctypes.data)
    )


@njit(cache=True)
def send_ghost_forces(force, torque, other, mpi, mail):
    """Each rank's rows of force, torque and other side by side (3 + 3 + k doubles; other (n, k)
    a fluid's ghost array, k = 0 without one) to it, and those of the ghosts this rank holds from
    their owners, as RankSteps._swap sends them; returns MPI's first error code (0: none). Any
    three arrays of n rows whose widths sum to the boxes' serve (kernels/fluid/drag.py
    rank_cell_coefficients: its (n, 2) rows and two empty arrays)."""
    to, to_start, to_local, out, come, come_start, come_local, into, requests, statuses = mail
    second = force.shape[1]  # where torque's columns begin in a row, and other's
    third = second + torque.shape[1]
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
        rows_out(torque, local, box, second)
        rows_out(other, local, box, third)
        code = _post(mpi[2], box, to[m], mpi, requests[messages:])
        if code != 0:
            return code
        messages += 1
    code = call_c(mpi[3], (np.int32(messages), requests.ctypes.data, statuses.ctypes.data))
    if code != 0:
        return code
    for m in range(come.shape[0]):
        local = come_local[come_start[m] : come_start[m + 1]]
        box = into[come_start[m] : come_start[m + 1]]
        rows_in(box, local, force, 0)
        rows_in(box, local, torque, second)
        rows_in(box, local, other, third)
    return 0


@njit(cache=True)
def own_wall_sums(own, pforce, record, glued, glued_wall, force, mass, body_acc, sums):
    """This rank's share of the walls' exact sums (kernels/walls.py wall_totals) into sums
    (cleared first): the pushes of `own` (its own particles near the walls) and the glued spheres
    it owns (glued: local indices, glued_wall: the wall of each)."""
    clear_sums(sums)
    for i in own:
        add_pushes(pforce, i, record, sums)
    add_glued(glued, glued_wall, force, mass, body_acc, record, sums)


@njit(cache=True)
def rank_wall_totals(
    mpi, own, pforce, record, glued, glued_wall, force, mass, body_acc, sums, summed, fluid_force, wall_force
):  # fmt: skip
    """Collective: wall_force as one rank's wall_totals makes it, bitwise: each rank's share of
    the exact sums (own_wall_sums) added over the ranks (MPI_Allreduce, MPI_SUM of int64: exact,
    so in any order) into summed, then rounded. Returns MPI's error code."""
    own_wall_sums(own, pforce, record, glued, glued_wall, force, mass, body_acc, sums)
    code = call_c(
        mpi[0], (sums.ctypes.data, summed.ctypes.data, np.int32(sums.size), mpi[9], mpi[10], mpi[5])
    )
    if code != 0:
        return code
    finish_wall_totals(summed, record, fluid_force, wall_force)
    return 0


@njit(cache=True)
def rank_walls_kick(motion, mpi, step, done):
    """The walls' kick at the end of step `done` of a rank's loop from the clock's `step`
    (motion: rank_dem_steps's, or None where no wall moves): their areas, the particles' totals
    on them over every rank (rank_wall_totals), and their kick. Returns MPI's error code."""
    if motion is None:
        return 0
    wall_areas(*motion[1])
    code = rank_wall_totals(mpi, *motion[2])
    if code != 0:
        return code
    wall_kick(*motion[3], (step + done + 1) * motion[6], motion[6])
    return 0


@njit(cache=True)
def rank_dem_steps(
    steps, step, threshold2, drift, cross, pairs, walls, fluid, kicks, motion, budget, mpi, mail, scratch
):
    """Up to `steps` steps of a rank's part from the clock's `step` (kernels/steps.py dem_steps):
    returns (the complete steps taken, the last squared displacement over every rank, whether a
    drift made the list stale or a wall left the reach of the near-wall list (the caller ends
    that step), the seconds in the forces, MPI's first error code). motion: None where no wall
    moves, else dem_steps's with rank_wall_totals's arguments but mpi in place of
    listed_wall_totals's, and without the clock's step (the arguments outlive a call: the step
    comes with each). fluid: None, or the 1D VANS force's arguments (module docstring). budget:
    None, or the energy budget's as dem_steps takes them (each rank books the particles it
    holds; their owners' shares are the ones kept).
    scratch: (2,) float64, (2,) int64: the reduction's and the clock's."""
    moved, clock = scratch
    mine, largest = moved[:1], moved[1:]
    busy = 0.0
    force, torque = kicks[2], kicks[3]
    code, stale = 0, False
    kicked = False  # this step's kick-drift taken with the last step's kick (as dem_steps)
    for done in range(steps):
        if not kicked:
            code, stale = rank_drift(motion, drift, mpi, mine, largest, threshold2, False)
        if code != 0 or stale:
            return done, largest[0], stale, busy, code
        if budget is not None:
            keep_half_step(*budget[0])
        started = seconds(mpi, clock)
        contacts(cross, pairs, walls)
        if fluid is not None:
            fluid_force(*fluid)
        busy += seconds(mpi, clock) - started
        code = send_ghost_forces(force, torque, force[:, :0], mpi, mail)  # (n, 0): no fluid array
        if code != 0:
            return done, largest[0], False, busy, code
        code = rank_walls_kick(motion, mpi, step, done)
        if code != 0:
            return done, largest[0], False, busy, code
        kicked = motion is None and budget is None and done + 1 < steps
        if kicked:
            code, stale = rank_drift(motion, drift, mpi, mine, largest, threshold2, True)
        else:
            kick(*kicks)
            if budget is not None:
                accumulate_budget(*budget[1])
    return steps, largest[0], False, busy, 0


# one thread: the loop without parallel regions (kernels/serial.py)
drift_everywhere_serial = serial_twin(drift_everywhere, kick_drift=kick_drift_serial)
rank_drift_serial = serial_twin(rank_drift, drift_everywhere=drift_everywhere_serial)
rank_dem_steps_serial = serial_twin(
    rank_dem_steps,
    rank_drift=rank_drift_serial,
    kick=kick_serial,
    contacts=contacts_serial,
    accumulate_budget=accumulate_budget_serial,
)
