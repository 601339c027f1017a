"""Many DEM steps in one compiled call (physics/compiled_steps.py).

The step's kernels are called here in the order and with the arguments the Python hooks give
them (physics/motion.py, contact.py, walls.py), so the result is bitwise that of the step-by-step
loop; what is saved is the interpreter's share of a step: the hook calls and the conversion of
some 80 arguments, about 18 us a step on one thread. The loop stops after the kick-drift that
makes the neighbour list stale: the caller rebuilds the list and ends that step in Python.

Arguments: steps, the most to take; threshold2 [m^2], the squared half skin; drift, cross,
pairs, walls and kick, the argument tuples of kick_drift, cross_chunk_pairs (None with one
chunk), chunk_pair_forces, wall_forces (None without walls) and kick; fluid, None, or the
arguments of a fluid's force on the particles that is one kernel, called after the contacts
where the forces hooks put it: `fluid_force` below, which the fluid's variant of the loop
replaces by its kernel (kernels/serial.py variant; the 1D VANS's, kernels/fluid/profile_forces.py
vans1d_steps), so that this module imports nothing of a fluid; motion, None where no wall
moves, else (the argument tuples of wall_kick_drift, wall_areas, listed_wall_totals (the
near-wall list first) and of wall_kick but its time and dt, the wall positions the list of
particles near walls was made at, half the skin [m], the clock's step at the call, dt [s]): the
walls move before the particles drift and are kicked before them, as their hooks run
(physics/walls.py WallMotion); budget, None without the energy budget, else the argument tuples
of keep_half_step and accumulate_budget (kernels/observe/energy_budget.py), called before the
contacts and after the kick as its hooks are. Returns (the complete steps taken, the last
squared displacement, whether a drift ended the loop: a particle beyond half the skin, or a wall
as far from where the near-wall list was made, which the wall hook then makes again).
chunked_walls: wall_forces's arguments with the near-wall list cut at chunk_pair_forces's
chunks' bounds (None without walls), for chunk_steps_end, which takes a step's sweep, walls and
next kick-drift where the pairs are swept in several chunks (more than one thread), no fluid's
force comes between and nothing between the kick and the next kick-drift.
A fluid whose step between its own needs more (the Navier-Stokes drag's exact kick and its
sums over cells) has its own loop calling `contacts` and its kernels (kernels/fluid/drag.py
drag_steps): a kernel passed as an argument would key Numba's cache by an object that differs
in every process, so it would compile on every run."""

from numba import njit, prange

from .contact import BOUNDS, chunk_pair_forces, chunk_pair_forces_serial, cross_chunk_pairs, one_chunk
from .motion import kick, kick_drift, kick_drift_serial, kick_serial, particles_of
from .observe.energy_budget import accumulate_budget, accumulate_budget_serial, keep_half_step
from .serial import serial_twin
from .walls import (
    listed_wall_totals,
    one_piece,
    wall_areas,
    wall_forces,
    wall_forces_serial,
    wall_kick,
    wall_kick_drift,
)


@njit(cache=True)
def contacts(cross, pairs, walls):
    """The pair contacts, then the walls' (the forces hooks' order)."""
    if cross is not None:
        cross_chunk_pairs(*cross)
    chunk_pair_forces(*pairs)
    if walls is not None:
        wall_forces(*walls)


@njit(cache=True, parallel=True)
def chunk_steps_end(pairs, walls, drift):
    """A step's pair sweep and walls and the next step's kick-drift with this step's kick, in
    one parallel region, chunk by chunk: in chunk c chunk_pair_forces_serial (its chunk c),
    wall_forces_serial (its piece c: `walls` cut at the chunks' bounds) and kick_drift's serial
    twin (the chunk's particles), as chunk_pair_forces and wall_forces call the first two. A
    chunk's sweep reads and writes only its own particles and the slots cross_chunk_pairs filled
    before, so its particles' forces are whole once it ends, and their walls and kick-drift
    follow at once, while other threads sweep their chunks; each particle's sums and steps are
    those of contacts and kick_drift one after the other. Where threads sleep between regions
    (OMP_WAIT_POLICY=PASSIVE), each region first wakes them: two regions a step fewer. Returns
    the largest squared displacement (kick_drift's)."""
    bounds = pairs[BOUNDS]
    worst = 0.0
    for c in prange(bounds.shape[0] - 1):
        chunk_pair_forces_serial(*one_chunk(pairs, c))
        if walls is not None:
            wall_forces_serial(*one_piece(walls, c))
        largest = kick_drift_serial(*particles_of(drift, bounds[c], bounds[c + 1]), True)
        worst = max(worst, largest)
    return worst


@njit(cache=True)
def walls_moved(coord, listed_at, reach):
    """True if a wall is `reach` [m] or more from where the near-wall list was made (the test of
    physics/walls.py PlaneWallForces._near_walls)."""
    for w in range(coord.shape[0]):
        if abs(coord[w] - listed_at[w]) >= reach:
            return True
    return False


@njit(cache=True)
def walls_kick(motion, done):
    """The walls' kick at the end of the loop's step `done` (motion: dem_steps's, or None where
    no wall moves): their areas, the particles' totals on them, and their kick."""
    if motion is not None:
        wall_areas(*motion[1])
        listed_wall_totals(*motion[2])
        wall_kick(*motion[3], (motion[6] + done + 1) * motion[7], motion[7])


@njit(cache=True)
def fluid_force(*arguments):
    """The place of a fluid's force in the loops (module docstring): never called here, where
    `fluid` is None and Numba leaves the call out."""


@njit(cache=True)
def dem_steps(steps, threshold2, drift, cross, pairs, walls, fluid, kicks, motion, budget, chunked_walls):
    moved2 = 0.0
    kicked = False  # this step's kick-drift taken with the last step's kick
    for done in range(steps):
        if not kicked:
            if motion is not None:
                wall_kick_drift(*motion[0])
            moved2 = kick_drift(*drift, False)
        if moved2 > threshold2:
            return done, moved2, True
        if motion is not None and walls_moved(motion[0][4], motion[4], motion[5]):
            return done, moved2, True
        if budget is not None:
            keep_half_step(*budget[0])
        kicked = motion is None and budget is None and done + 1 < steps
        if kicked and cross is not None and fluid is None:  # chunks on several threads
            cross_chunk_pairs(*cross)
            moved2 = chunk_steps_end(pairs, chunked_walls, drift)
            continue
        contacts(cross, pairs, walls)
        if fluid is not None:
            fluid_force(*fluid)
        walls_kick(motion, done)
        # with nothing between the kick and the next step's kick-drift, both in one pass
        if kicked:
            moved2 = kick_drift(*drift, True)
        else:
            kick(*kicks)
            if budget is not None:
                accumulate_budget(*budget[1])
    return steps, moved2, False


# one thread: the same loop without parallel regions (kernels/serial.py); one chunk, so no
# pairs across chunks
contacts_serial = serial_twin(
    contacts, chunk_pair_forces=chunk_pair_forces_serial, wall_forces=wall_forces_serial
)
dem_steps_serial = serial_twin(
    dem_steps,
    kick_drift=kick_drift_serial,
    kick=kick_serial,
    contacts=contacts_serial,
    accumulate_budget=accumulate_budget_serial,
)
