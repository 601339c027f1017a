"""The DEM steps of one scene split across MPI ranks (sphere_cli/ranks.py): slabs of search
cells, ghosts one cell wide, particles moving between ranks only at neighbour-list builds, and
results bitwise those of one rank, whatever the rank count.

**Slabs or pencils.** The box is cut along one axis into one slab of whole search cells per
rank, or along two into pencils, p x q ranks (physics/neighbors.py search_cells), each axis cut
where the particles are shared evenly (or, with simulation.rank_balance = "time", the measured
work) at each list build (a cut never changes a result). The cut is chosen again each time: of
the slabs along each axis with a cell for every rank and the pencils along each pair of axes
and each p x q that fits them (a pair of more than PENCIL_GRID_CELLS cells only where no slabs
fit: its counts are summed over the ranks at each cut), the one whose busiest rank holds the
fewest particles, own and ghosts, the last one kept unless another holds 2 % fewer (a bed lying
in a tall box is cut across its width, not through its few layers: finer shares, thinner ghost
layers and each rank its part of the floor; a square bed between walls on four ranks into 2 x 2
pencils). A rank owns the particles whose position at the last list build lies in its part,
and holds as ghosts those within one cell of it, diagonals included: every pair listed at that
build then lies within one rank's particles, own or ghost, until the next build.

**Same bits.** A rank keeps its particles in ascending global index and runs the one-rank step
on them (Motion, NeighborSearch, PairContactForces, PlaneWallForces), so each owned particle
sums m g, its pairs (j, i) and its own row in the order one rank does (kernels/contact.py), and
each pair across a cut is computed on both sides with the same inputs and spring. A ghost's
force misses its pairs beyond the ghosts: after the forces, each owner sends its ghosts' force
and torque, so that every rank's kick, and next drift, of a ghost is its owner's, bit for bit.
The pairs of two ghosts are therefore left out of a rank's list (kernels/neighbors.py
drop_ghost_pairs): they would add only to forces that their owners' replace.
The largest displacement that decides a rebuild is the maximum over ranks (exact in any order).
The stability check runs on every rank, on its particles and its view of a fluid; the lead
gathers the scene to report the first failure only when some rank finds one.

**At a build** the owners send each particle, with its half row of springs by global index and
its wall springs, to the other ranks that own or hold it next, and keep those they hold next;
each rank builds its list from the positions, carrying each pair's spring from those rows as
one rank carries it from its last list (NeighborSearch.rebuild). The rows' width
follows the longest row over all ranks, so a checkpoint's layout is one rank's.

**The host.** The lead keeps the whole scene (physics/rank_steps is its scene.step.compiled,
like a GPU's physics/device_steps.py): `to_host` gathers the owners' particles and rows into it
before frames, observables and checkpoints, so files are those of one rank and a checkpoint
resumes on any rank count. A part's steps up to a list build run in one compiled call with
their messages inside (kernels/rank_messages.py, through physics/rank_calls.py), moving walls,
the energy budget and a 1D VANS fluid's force included, and the Navier-Stokes drag's own loop
(kernels/fluid/drag.py rank_drag_steps) without the budget (RankSteps.in_compiled_loop); with
the Darcy fluid, or the budget beside the Navier-Stokes drag, one at a time in Python with
mpi4py's messages (an exchange of ghost forces and one reduction a step), as on a rank
holding no particle.

**Moving walls** are stepped on every rank alike; the particles' force on them is summed
exactly (kernels/exact_sum.py): each rank adds its own particles' share into the sums' words
and one Allreduce adds those (kernels/rank_messages.py rank_wall_totals, or `_wall_kick` from
Python, with the same message), one rank's total bitwise. **Stages** run at the lead on its whole scene,
gathered for the steps where a stage may end; when one begins, the scene is shared out again.
A **fluid** keeps its own arrays (profiles, grids) whole on every rank. Its force and kick run
on every rank, its per-particle arrays (`particle_arrays`) travelling with the particles; those
its force writes from the other forces on a particle (`ghost_arrays`: the Navier-Stokes drag's
f_other) go to the ghosts with the force, and a sum over particles inside its kick (the
Navier-Stokes self-induced velocity's drag coefficients per cell) is taken, for the cells
this rank's particles can visit, over every rank's own particles in them in global order
(the rows of each rank's own particles that can be in them, planned at each list build:
`FluidModule.plan_rank_steps`, and sent at each step from the compiled loop or `_swap`).
Its own step (its `step_on_rank`: the VANS column, the Darcy pore pressure, the
Navier-Stokes grid) runs on every rank alike from the particles its cells (the grid's slabs of
x planes) or layers (the VANS column's, shared out) reach and their fluid arrays, taken from
every rank's owners in global order (`_near`), nothing gathered at the lead nor sent back: the
grids are cut only for the pressure solve, the porosity, the Navier-Stokes momentum exchange
and prediction (physics/fluid/poisson.py Slabs), and each rank computes the rest of the fluid
whole. A failure there is met by every rank at once and reported by the lead alone.

It covers the particles, their pair contacts (both laws, friction, rolling, materials),
gravity, walls of every mode, stages, periodic boundaries and the fluids coupled to particles
(1D VANS, Darcy, Navier-Stokes), and the energy budget: each rank books its own particles'
shares (EnergyBudget.booked, their rows as one rank has them), which travel with the particles.
A fluid without particles and the GPU are refused with what they are named.
"""

from __future__ import annotations

import copy
import itertools
import math
import time
import types
import warnings
from dataclasses import dataclass
from typing import NamedTuple

import numba
import numpy as np

from ..errors import UsageError
from ..kernels.motion import first_unstable, kick, kick_drift, kick_drift_serial, kick_serial
from ..kernels.neighbors import (
    drop_ghost_pairs,
    fill_rows,
    local_partners,
    merge_rows,
    row_starts,
    rows_by_global_index,
    rows_in,
    rows_out,
)
from ..kernels.rank_messages import TAG, own_wall_sums, rank_dem_steps, rank_dem_steps_serial
from ..kernels.serial import use_serial
from ..kernels.steps import contacts, contacts_serial
from ..kernels.walls import finish_wall_totals, wall_areas, wall_kick
from ..state import Clock, NeighborList, Particles, State, Walls
from .compiled_steps import plain_step, step_arguments
from .contact import PairContactForces
from .neighbors import SPRING_ROOM, NeighborSearch
from .observe.energy_budget import EnergyBudget
from .rank_calls import compiled_calls, ghost_mail
from .walls import PlaneWallForces, WallMotion, wall_sums

# per-particle arrays a particle carries between ranks (Particles; the predicted velocities
# too: the kick-drift of a build's step set them, and the forces read them)
CARRIED = (*Particles.PROGNOSTIC, "vel_pred", "angvel_pred")
# a cut along other axes, or into other parts, replaces the last one only where its busiest rank
# holds this fraction fewer particles: each change moves most particles between ranks
SWITCH_GAIN = 0.02
# pencils along a pair of axes are weighed from the particles counted in each of their cells_a x
# cells_b cells over every rank (an Allreduce at each cut): a pair with more cells is left out
# where slabs fit (the sparse scene of `sphere bench dem`, 900^3 cells: 6.5 MB a pair)
PENCIL_GRID_CELLS = 2**18
# seconds a follower whose fluid step failed waits before it reports the failure itself: every
# rank takes the same step from the same arrays and meets the same failure, which the lead
# reports as one rank does, ending every rank; what fails on one rank alone is its own
FAILURE_GRACE = 30.0
# the modules split across ranks (the stages and the Observer act on the lead's whole scene)
SUPPORTED = (
    "wall_motion",
    "particles",
    "neighbors",
    "contact",
    "walls",
    "fluid",
    "stages",
    "observables",
    "energy_budget",
    "",
)
# the walls' arrays every rank keeps, each the same on every rank (all but the per-particle
# springs, forces and glued spheres)
WALL_FIELDS = (
    "faces", "axis", "sign", "coord", "table", "vel", "acc", "shift", "force", "area", "mode", "control",
    "vel_pred", "record", "fluid_force",
)  # fmt: skip
# the prefix of a fluid's per-particle arrays in a pack
FLUID = "fluid:"
# those a step changes: moving walls, a fluid's push (brought back to the lead's scene with the
# particles)
STEPPED_WALL_FIELDS = ("coord", "vel", "acc", "shift", "force", "area", "vel_pred", "fluid_force")


@dataclass
class Template:
    """What a follower needs to run its part of a scene (sent once by the lead)."""

    box: object
    dt: float
    step: int
    tables: object
    table: np.ndarray  # the contact table now (a stage sets its friction)
    springs: bool
    skin: float
    threshold2: float
    walls: dict | None  # WALL_FIELDS of the lead's walls, or None
    moving: bool  # some wall moves (WallMotion)
    attached: np.ndarray  # (K,) global indices of the spheres glued to walls
    attached_wall: np.ndarray  # (K,) their wall
    count: int  # the scene's particles, on every rank together
    axes: tuple  # the axes a cut may follow: those at least two search cells wide
    lower: np.ndarray  # (3,) the box's lower corner [m]
    cell: np.ndarray  # (3,) search cells' width along each axis [m]
    cells: np.ndarray  # (3,) int64 search cells along each axis
    periodic: np.ndarray  # (3,) bool, each axis periodic
    capacity: int  # the rows' width
    builds: int  # list builds so far
    builds_since_growth: int
    threads: int | None  # simulation.threads (None: each rank its share of its node's cores)
    balance: str  # simulation.rank_balance: the slabs cut by particles held, or by measured work
    fluid: object = None  # the lead's fluid module (FluidModule with particle_arrays), or None
    fluid_state: object = None  # its state.fluid
    budget: bool = False  # the energy budget is kept (each particle's share travels with it)


@dataclass
class Part:
    """The particles a rank holds, own and ghosts, in ascending global index, with the modules
    that step them."""

    gid: np.ndarray  # (n,) int64 global index of each
    owned: np.ndarray  # (n,) bool
    state: State
    search: NeighborSearch
    contact: PairContactForces
    walls: PlaneWallForces | None
    wall_motion: WallMotion | None
    fluid: object  # this rank's copy of the fluid module (its particles' arrays), or None
    budget: EnergyBudget | None  # the energy budget of its particles' shares, or None
    glued: np.ndarray  # (k,) local indices of the glued spheres held here
    glued_order: np.ndarray  # (k,) their places in the lead's list of glued spheres
    send: dict  # rank -> local indices of own particles that are ghosts there, ascending
    receive: dict  # rank -> local indices of the ghosts it owns, ascending
    own: np.ndarray | None = None  # its own particles' local indices (RankSteps._own)
    # the ghosts' messages (RankSteps._ghost_forces): the boxes received and sent, by rank, made
    # at the part's first step
    mail: tuple | None = None
    # the same for the compiled steps (physics/rank_calls.py ghost_mail), made at their first call
    compiled_mail: tuple | None = None


class StepCalls(NamedTuple):
    """A part's kernels as (kernel, arguments): the kick-drift, the contacts, the kick, and the
    compiled loop of whole steps (None where the part's step is not all in it)."""

    drift: tuple | None
    contacts: tuple | None
    kick: tuple | None
    loop: tuple | None


def _refusal(scene) -> str | None:
    """What of the scene's step the ranks do not run, in words (None: they run all of it)."""
    extra = [m.name for m in scene.modules if m.name not in SUPPORTED]
    if scene.state.particles.count == 0:
        extra.append("no particles (a fluid-only case)")
    fluid = scene.fluid
    if fluid is not None and (
        fluid.particle_arrays(scene.state) is None or not hasattr(fluid, "step_on_rank")
    ):
        extra.append(f"a {scene.fluid.model} fluid, which does not run split")
    if scene.case.simulation.device != "cpu":
        extra.append(f'simulation.device = "{scene.case.simulation.device}"')
    if not extra and (scene.neighbors is None or not plain_step(scene, budget=True)):
        extra.append("other step hooks")
    return ", ".join(extra) or None


class EveryRank:
    """The `whole` a fluid's rank_copy and step_on_rank are given, what they take of the whole
    scene (collectives): near(needed, *arrays), called with arrays of this rank's particles,
    those of every rank's own particles that needed(own) ((ranks, n) bool of own, the local
    indices of an owner's own particles) marks for this rank, in global order (RankSteps._near);
    own() this rank's own particles; every_mask(mask) every rank's mask, packed; alltoall(objects) an
    object from every rank; swap(columns, send, receive, boxes) the rows of a message to and from
    each rank, as the compiled loops send them (boxes(send, receive, width) its boxes,
    mail(send, receive, width) the compiled loops' form of them)."""

    def __init__(self, steps: RankSteps):
        self.steps = steps

    @property
    def rank(self) -> int:
        return self.steps.world.rank

    def gid(self) -> np.ndarray:
        """The global index of each particle this rank holds (ascending)."""
        return self.steps.part.gid

    def alltoall(self, objects: list) -> list:
        """objects[r] to rank r; returns what each rank sent this one (pickled: for plans made
        at list builds or fluid steps, not every step)."""
        return self.steps.world.comm.alltoall(objects)

    @staticmethod
    def boxes(send: dict, receive: dict, width: int) -> tuple[dict, dict]:
        """The boxes of swap's messages, `width` doubles a row: (received, sent) by rank."""
        return tuple({r: np.empty((rows.size, width)) for r, rows in by.items()} for by in (receive, send))

    def swap(self, columns: list, send: dict, receive: dict, boxes: tuple) -> None:
        self.steps._swap(columns, send, receive, boxes)

    def mail(self, send: dict, receive: dict, width: int) -> tuple:
        """swap's message as the compiled loops send it (kernels/rank_messages.py
        send_ghost_forces, with its columns the first array's)."""
        return ghost_mail(self.steps.world, send, receive, self.steps.calls[1], width)

    def near(self, needed, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
        return self.steps._near(needed, *arrays)

    def own(self) -> np.ndarray:
        """The local indices of this rank's own particles (ascending)."""
        return self.steps._own()

    def every_mask(self, mask: np.ndarray) -> np.ndarray:
        """(ranks, ceil(m / 8)) uint8: every rank's mask (m,) bool as np.packbits packs it (one
        Allgather of its bits), left packed: unpacked, the masks of many ranks over a large grid
        would take eight times the memory."""
        packed = np.packbits(mask)
        every = np.empty((self.steps.world.size, packed.size), dtype=np.uint8)
        self.steps.world.comm.Allgather(packed, every)
        return every


def summed_over_ranks(world, sums: np.ndarray) -> np.ndarray:
    """Collective: the words of every rank's exact sums (int64) added over the ranks, exactly:
    the message of kernels/rank_messages.py rank_wall_totals, from Python."""
    summed = np.empty_like(sums)
    world.comm.Allreduce([sums, world.mpi.INT64_T], [summed, world.mpi.INT64_T], op=world.mpi.SUM)
    return summed


class RankSteps:
    """scene.step.compiled on every rank of a split run (the lead's holds the whole scene)."""

    # takes any number of whole steps, list builds included (simulation.advance)
    whole_steps = True

    def __init__(self, world, template: Template):
        self.world = world
        self.t = template
        self.part: Part | None = None
        self.pids: list[int] = []
        # the last cut: (axis, first cell of each part along it and the end) for one axis (slabs)
        # or two (pencils, rank = index along the first x parts along the second + index along
        # the second)
        self.cut: tuple = ((0, np.array([0, 1], dtype=np.int64)),)
        self.busy = 0.0  # seconds in this rank's forces since the last cut (rank_balance = "time")
        self.at_step = None  # the lead: the host step the ranks' particles are for (None: send)
        self.host_stale = False  # the lead: steps taken since the last gather
        self.host_search = None  # the lead: its scene's NeighborSearch
        self.contact = None  # the lead: its scene's PairContactForces (a stage sets its table)
        self.stages = None  # the lead: its scene's Stages
        self.fluid = None  # the lead: its scene's fluid module
        self.budget = None  # the lead: its scene's EnergyBudget
        self.every = EveryRank(self)  # what a fluid's step on the rank sums over
        # the MPI functions of the compiled steps (rank_calls.compiled_calls; () where not found)
        self.calls = None

    # --- set-up ----------------------------------------------------------------------------

    @classmethod
    def of(cls, scene, world) -> RankSteps:
        """The lead's rank steps of a scene, or a UsageError saying what does not run split."""
        refused = _refusal(scene)
        if refused is not None:
            raise UsageError(
                f"started as {world.size} MPI ranks: a scene split across ranks runs the particles, "
                "their pair contacts, gravity, walls (fixed, moving, stress-controlled), stages, "
                "periodic boundaries and the fluids coupled to particles; this case also has: "
                f"{refused}. Run it as one process (threads: "
                "simulation.threads)."
            )
        search, state = scene.neighbors, scene.state
        axes = tuple(a for a in range(3) if search.ncell[a] >= 2)
        slabs = any(search.ncell[a] >= world.size for a in axes)
        if not slabs and not any(
            _pencils(world.size, *search.ncell[list(ab)]) for ab in itertools.combinations(axes, 2)
        ):
            widest = int(np.argmax(search.ncell))
            raise UsageError(
                f"started as {world.size} MPI ranks: the box is {int(search.ncell[widest])} search cells "
                f"wide along its widest axis ({'xyz'[widest]}) and each rank needs a slab at least one cell "
                f"wide, or a pencil of p x q ranks a cell along each of two axes; use at most "
                f"{int(search.ncell[widest])} ranks, or a product of two that fits the box"
            )
        template = Template(
            box=state.box,
            dt=state.clock.dt,
            step=state.clock.step,
            tables=scene.contact.tables,
            table=scene.contact.table,
            springs=search.springs,
            skin=state.neighbors.skin,
            threshold2=search.threshold2,
            walls=None,
            moving=scene.wall_motion is not None,
            attached=np.zeros(0, dtype=np.int64),
            attached_wall=np.zeros(0, dtype=np.int64),
            count=state.particles.count,
            axes=axes,
            lower=np.array(state.box.lower, dtype=np.float64),
            cell=np.array(search.cell_size, dtype=np.float64),
            cells=np.array(search.ncell, dtype=np.int64),
            periodic=np.array(state.box.periodic, dtype=bool),
            capacity=state.neighbors.nbr.shape[1],
            builds=state.neighbors.builds,
            builds_since_growth=search.builds_since_growth,
            threads=scene.case.simulation.threads,
            balance=scene.case.simulation.rank_balance,
            budget=scene.budget is not None,
        )
        steps = cls(world, template)
        steps.host_search = search
        steps.contact = scene.contact
        steps.stages = scene.stages
        steps.fluid = scene.fluid
        steps.budget = scene.budget
        world.order("start", template)
        steps.pids = world.pids()
        return steps

    @classmethod
    def following(cls, world, template: Template) -> RankSteps:
        """A follower's rank steps, from the lead's "start"."""
        steps = cls(world, template)
        steps.pids = world.pids()
        if template.threads is not None:
            numba.set_num_threads(min(template.threads, numba.config.NUMBA_NUM_THREADS))
        return steps

    def describe(self) -> str:
        """For run.log: ranks, how the slabs are cut and processes."""
        by = "measured work" if self.t.balance == "time" else "particles held"
        how = (
            "each rank's steps up to a list build in one compiled call"
            if self.in_compiled_loop()
            else "each rank's steps one at a time from Python (a Darcy fluid, a Navier-Stokes drag with "
            "the energy budget, or an MPI whose functions mpi4py's library does not give)"
        )
        return (
            f"split across {self.world.size} MPI ranks, slabs or pencils of search cells cut by {by} "
            "along the axes where the busiest rank holds the fewest, chosen again at each list build; "
            f"{how} (process ids by rank: {' '.join(map(str, self.pids))})"
        )

    # --- the lead's side (simulation.advance and check_stable call these) --------------------

    def _send_out(self, state: State) -> None:
        """The lead's whole scene shared out to the ranks (at the first steps, and again
        whenever the host's state is not the ranks' own)."""
        t = self.t
        t.step, t.capacity, t.builds = state.clock.step, state.neighbors.nbr.shape[1], state.neighbors.builds
        t.builds_since_growth = self.host_search.builds_since_growth
        t.table = self.contact.table
        walls = state.walls
        if walls is not None:
            t.walls = {name: getattr(walls, name) for name in WALL_FIELDS}
            t.attached, t.attached_wall = walls.attached, walls.attached_wall
        t.fluid, t.fluid_state = self.fluid, state.fluid
        self.world.order("share", t)
        n = state.particles.count
        every = np.arange(n)
        self._share([_pack(state, every, every, t.springs, state.neighbors.ref_pos, self.fluid, self.budget)])
        self.at_step = state.clock.step

    def run(self, state: State, steps: int) -> tuple[int, bool]:
        def work():
            # again from the lead's scene when it is not the ranks' (a stage that began has set
            # walls, friction and perhaps moved glued spheres)
            stage_began = self.stages is not None and self.stages.ended_at == state.clock.step
            if self.at_step != state.clock.step or stage_began:
                self._send_out(state)
            self.world.order("steps", steps)
            self._steps(steps)

        self.world.together(work, self._progress)
        self.at_step = state.clock.step + steps
        if self.fluid is not None and self.fluid.after_due(self.at_step, state.clock):
            self.fluid.stepped_on_ranks = self.at_step  # taken in _steps, on every rank
        self.host_stale = True
        if self.stages is not None and self.stages.after_due(self.at_step, state.clock):
            self.to_host(state)  # a stage's test reads the lead's scene (and only there)
        return steps, False

    def _progress(self) -> dict:
        """The step and time the ranks have reached (status.json of a run that fails there;
        none before the scene is first shared out)."""
        if self.part is None:
            return {}
        clock = self.part.state.clock
        return {"step": clock.step, "time": clock.time}

    def hand_over(self, state: State) -> None:
        """to_host: on ranks the steps are called only by the run loop and the benchmark
        (a script's run on ranks is refused, ranks.py), which do not change the scene between
        calls."""
        self.to_host(state)

    def to_host(self, state: State) -> None:
        """The owners' particles, rows and wall springs into the lead's scene."""
        if not self.host_stale:
            return

        def work():
            self.world.order("gather")
            capacity = self.part.state.neighbors.nbr.shape[1]
            _unpack_into_host(state, self._gather(), capacity, self.t.springs, self.fluid, self.budget)

        self.world.together(work)
        if state.walls is not None:  # the walls, the same on every rank: the lead's own
            for name in STEPPED_WALL_FIELDS:
                getattr(state.walls, name)[...] = getattr(self.part.state.walls, name)
        self.host_search.builds_since_growth = self.part.search.builds_since_growth
        state.neighbors.builds = self.part.state.neighbors.builds
        self.host_search._spare_like(state.neighbors)
        self.host_stale = False

    def known_stable(self, state: State) -> bool:
        """True when no rank holds a particle gone bad, nor sees its fluid gone bad (then the
        host checks itself, to report the first as one rank does)."""
        if not self.host_stale:
            return False

        def work():
            self.world.order("stable")
            return self._stable()

        return self.world.together(work)

    # --- every rank -------------------------------------------------------------------------

    def carry_out(self, command: str, *args) -> None:
        """A follower carries out the lead's command."""
        if command == "steps":
            self._steps(*args)
        elif command == "gather":
            self._gather()
        elif command == "stable":
            self._stable()
        elif command == "share":
            self.t = args[0]
            self._share([])
        else:
            raise RuntimeError(f"unknown command {command!r} from the lead")

    def _steps(self, steps: int) -> None:
        """The one-rank step on this rank's particles (physics/module.py order), with the ghosts'
        forces from their owners and the rebuild decided over every rank. A part in the
        compiled loop (in_compiled_loop) takes its steps in one compiled call
        (kernels/rank_messages.py) up to a list build or a wall's move out of its near-wall
        list's reach, and that step ends here; its fluid's step, if due, then follows here."""
        moved, largest = np.zeros(1), np.zeros(1)
        fluid_kicks = self.t.fluid is not None and "kick" in self.t.fluid.takes_over
        self._plan_fluid()
        calls = self._kernels()
        left = steps
        while left > 0:
            if calls.loop is not None:
                step = self.part.state.clock.step
                taken, moved2, stale, busy, code = calls.loop[0](left, step, *calls.loop[1])
                if code != 0:
                    raise RuntimeError(f"MPI error {code} in the ranks' compiled steps")
                if self.part.fluid is not None:  # what its loop found (the drag's porosity floor)
                    self.part.fluid.steps_taken(self.part.state, taken)
                self.part.state.clock.step += taken
                self.part.state.neighbors.moved2 = moved2
                self.busy += busy
                if not stale:
                    if taken < left:  # the fluid's loop stopped to report (its arguments made again)
                        calls = self._kernels()
                    left -= taken
                    continue
                left -= taken
                # the drift of the next step is taken: the list built (or the near-wall list
                # made again for walls that have moved), then the step ended here
                if moved2 > self.t.threshold2:
                    self._rebuild()
                calls = self._kernels()
            else:
                if self._drift_and_decide(calls, moved, largest):
                    calls = self._kernels()
            self._rest_of_step(calls, fluid_kicks)
            left -= 1
        state = self.part.state
        fluid = self.t.fluid
        if fluid is not None and fluid.after_due(state.clock.step, state.clock):
            try:
                with warnings.catch_warnings():
                    if not self.world.leads:  # the same step's at the lead warns of the same
                        warnings.simplefilter("ignore")
                    self.part.fluid.split_grid(self.world.grid_comm)
                    self.part.fluid.step_on_rank(state, self.every, self.part.gid)
            except Exception:
                if not self.world.leads:  # the lead reports it, as one rank does, and ends them
                    time.sleep(FAILURE_GRACE)
                raise

    def _drift_and_decide(self, calls, moved: np.ndarray, largest: np.ndarray) -> bool:
        """The step's kick-drift, and the list built again if a particle on any rank has moved
        half the skin since the last build; True if it was."""
        part = self.part
        state = part.state
        if part.wall_motion is not None:
            part.wall_motion.kick_drift(state)
        if state.particles.count:
            state.neighbors.moved2 = calls.drift[0](*calls.drift[1], False)
        moved[0] = state.neighbors.moved2
        self.world.comm.Allreduce(moved, largest, op=self.world.mpi.MAX)
        state.neighbors.moved2 = float(largest[0])
        if state.neighbors.moved2 > self.t.threshold2:
            self._rebuild()
            return True
        return False

    def _rest_of_step(self, calls, fluid_kicks: bool) -> None:
        """The step after its kick-drift: forces, the ghosts' forces from their owners, kick."""
        part = self.part
        state = part.state
        started = time.perf_counter()
        if part.budget is not None:  # before the contacts: it keeps the springs of the last step
            part.budget.forces(state)
        if state.particles.count:
            if part.wall_motion is None:
                calls.contacts[0](*calls.contacts[1])
            else:  # the walls have moved: their near-wall list may be out of date
                part.contact.forces(state)
                if part.walls is not None:
                    part.walls.forces(state)
        if part.fluid is not None:  # (on a rank without particles too: a fluid may push a wall)
            part.fluid.forces(state)
        self.busy += time.perf_counter() - started
        self._ghost_forces()
        if part.wall_motion is not None:
            self._wall_kick(state)
        if fluid_kicks:  # on every rank, its sums over all particles (rank_copy) a collective
            part.fluid.kick(state)
        elif state.particles.count:
            calls.kick[0](*calls.kick[1])
        if part.budget is not None:
            part.budget.finish_step(state)
        state.clock.step += 1

    def _kernels(self) -> StepCalls:
        """The kick-drift, the contacts (pairs, then plane walls) and the kick of this rank's
        part as (compiled kernel, its arguments), those the hooks Motion.kick_drift,
        PairContactForces.forces, PlaneWallForces.forces and Motion.kick call, as
        kernels/steps.py does for one rank: the arguments made once a list build, not once a
        step (120 beads on 2 ranks: 64 -> 55 us a step); and, where in_compiled_loop, the loop
        of those steps with their messages (kernels/rank_messages.py), moving walls, the energy
        budget and a 1D VANS fluid's force included, or the Navier-Stokes drag's own loop (its
        arguments valid until the fluid's next step, which ends the call; the drag's plan of
        its cells' sums made before, _plan_fluid). Valid until the next build while no wall
        moves, and for the loop until the next build or a wall's move beyond the reach of the
        near-wall list (the loop stops there)."""
        part = self.part
        state = part.state
        if not state.particles.count:
            return StepCalls(None, None, None, None)
        serial = use_serial()
        drift, cross, pairs, walls, kicks = step_arguments(state, part.contact, part.walls)
        loop = None
        if self.in_compiled_loop():
            mpi, request_type = self.calls
            own_loop = part.fluid is not None and part.fluid.rank_steps_kernels is not None
            if part.compiled_mail is None:  # the rows of _ghost_forces's message, which the loops send
                width = sum(c.shape[1] for c in _ghost_rows(part))
                part.compiled_mail = ghost_mail(self.world, part.send, part.receive, request_type, width)
            scratch = (np.zeros(2), np.zeros(2, dtype=np.int64))
            mail = part.compiled_mail
            motion = None if part.wall_motion is None else self._motion(state)
            if own_loop:  # the fluid's loop, its kick in place of the particles'
                drag, fluid_kicks = part.fluid.force_arguments(state), part.fluid.kick_arguments(state)
                arguments = (self.t.threshold2, drift, cross, pairs, walls, drag, fluid_kicks, motion)
                loop = (part.fluid.rank_steps_kernels[1 if serial else 0], (*arguments, mpi, mail, scratch))
            else:
                fluid, loop = None, rank_dem_steps_serial if serial else rank_dem_steps
                if part.fluid is not None:  # its variant of the loop, with its force in it
                    fluid = part.fluid.force_arguments(state)
                    loop = part.fluid.force_loops[3 if serial else 2]
                budget = None
                if part.budget is not None:
                    budget = (part.budget.keep_arguments(state), part.budget.book_arguments(state))
                arguments = (
                    self.t.threshold2, drift, cross, pairs, walls, fluid, kicks, motion, budget, mpi, mail,
                    scratch,
                )  # fmt: skip
                loop = (loop, arguments)
        return StepCalls(
            (kick_drift_serial if serial else kick_drift, drift),
            (contacts_serial if serial else contacts, (cross, pairs, walls)),
            (kick_serial if serial else kick, kicks),
            loop,
        )

    def in_compiled_loop(self) -> bool:
        """True if a part of this scene takes its steps in a compiled rank loop: no fluid, or
        one whose force the loop can take (FluidModule.force_loops: the 1D VANS), as the
        one-rank loop (physics/compiled_steps.py), or one with a rank loop of its own
        (FluidModule.rank_steps_kernels: the Navier-Stokes drag's) where no energy budget is
        kept; and the MPI functions found
        (physics/rank_calls.py compiled_calls)."""
        if self.calls is None:
            self.calls = compiled_calls(self.world.mpi, self.world.comm) or ()
        # the template's (the lead's own before the scene is first shared out: run.log's line)
        fluid = self.t.fluid if self.t.fluid is not None else self.fluid
        if fluid is not None and fluid.force_loops is None:
            if fluid.rank_steps_kernels is None or self.t.budget:
                return False
        return bool(self.calls)

    def _motion(self, state: State) -> tuple:
        """The `motion` argument of kernels/rank_messages.py rank_dem_steps: kernels/steps.py
        dem_steps's, with rank_wall_totals's arguments (this rank's own particles near the walls
        and own glued spheres with their walls) in place of listed_wall_totals's,
        and without the clock's step (the loop takes it at each call)."""
        part, w, p = self.part, state.walls, state.particles
        drift, areas, _, kick = WallMotion.kernel_arguments(state)
        near = w.listed  # as step_arguments made it
        totals = (
            near[part.owned[near]], w.pforce, w.record, *self._own_glued(), p.force, p.mass,
            state.box.body_acc, wall_sums(w), np.zeros_like(wall_sums(w)), w.fluid_force, w.force,
        )  # fmt: skip
        listed_at, reach = part.walls.near_list_made_at(state)
        return drift, areas, totals, kick, listed_at, reach, state.clock.dt

    def _fluid_for(self, state: State, pick):
        """The lead's fluid (the template's) for a rank's particles: its own arrays shared,
        state.fluid a copy, each of its particle_arrays pick(name, the lead's array)."""
        state.fluid = copy.copy(self.t.fluid_state)
        fluid = self.t.fluid.rank_copy(self.every)
        for name, (holder, attribute) in fluid.particle_arrays(state).items():
            setattr(holder, attribute, np.ascontiguousarray(pick(name, getattr(holder, attribute))))
        return fluid

    def _ghost_forces(self) -> None:
        """Each owner sends the force and torque of its particles that are ghosts elsewhere, and
        the fluid's ghost_arrays of them: one message to each rank, packed and unpacked by
        compiled loops in boxes made once a part."""
        part = self.part
        sent = _ghost_rows(part)
        if part.mail is None:  # the boxes, made once a part
            part.mail = EveryRank.boxes(part.send, part.receive, sum(c.shape[1] for c in sent))
        self._swap(sent, part.send, part.receive, part.mail)

    def _swap(self, columns: list, send: dict, receive: dict, boxes: tuple) -> None:
        """The rows `send[rank]` of the arrays `columns` (each (n, k)), side by side, to each
        rank, and the rows `receive[rank]` of them from each, with the messages of the compiled
        loops (kernels/rank_messages.py send_ghost_forces), so that a rank stepping from Python
        and one stepping in a compiled call meet; boxes: EveryRank.boxes's."""
        inbox, outbox = boxes
        comm = self.world.comm
        requests = [comm.Irecv(box, source=rank, tag=TAG) for rank, box in inbox.items()]
        for rank, local in send.items():
            first = 0
            for c in columns:
                rows_out(c, local, outbox[rank], first)
                first += c.shape[1]
            requests.append(comm.Isend(outbox[rank], dest=rank, tag=TAG))
        self.world.mpi.Request.Waitall(requests)
        for rank, local in receive.items():
            first = 0
            for c in columns:
                rows_in(inbox[rank], local, c, first)
                first += c.shape[1]

    def _own_glued(self) -> tuple[np.ndarray, np.ndarray]:
        """The glued spheres this rank owns (local indices) and the wall of each."""
        part = self.part
        glued = part.owned[part.glued]
        return part.glued[glued], self.t.attached_wall[part.glued_order[glued]]

    def _wall_kick(self, state: State) -> None:
        """WallMotion.kick with the particles' force on each wall summed as one rank sums it,
        bitwise, with the messages of the compiled loop's rank_wall_totals (ranks taking either
        meet): this rank's share of the exact sums (own_wall_sums), added over the ranks by an
        Allreduce of their words."""
        part, w, p = self.part, state.walls, state.particles
        _, areas, _, kick = WallMotion.kernel_arguments(state)
        wall_areas(*areas)
        near = w.listed  # the only rows of pforce that may not be zero
        sums = wall_sums(w)
        own_wall_sums(
            near[part.owned[near]], w.pforce, w.record, *self._own_glued(), p.force, p.mass,
            state.box.body_acc, sums,
        )  # fmt: skip
        finish_wall_totals(summed_over_ranks(self.world, sums), w.record, w.fluid_force, w.force)
        dt = state.clock.dt
        wall_kick(*kick, (state.clock.step + 1) * dt, dt)

    def _near(self, needed, *arrays: np.ndarray) -> tuple[np.ndarray, ...]:
        """Collective: the arrays (n, ...) of this rank's particles, of those of every rank's own
        particles that needed(own) ((ranks, n) bool of the owner's own particles, own their local
        indices) marks for this rank, in global index order: each owner sends each rank what it
        needs (one Alltoallv, the global index travelling as a column of doubles, exact below
        2^53), and each rank sorts what arrives by it."""
        own = self._own()
        part, comm, size = self.part, self.world.comm, self.world.size
        marks = needed(own)
        # each array as (n, k) doubles (k given: numpy cannot infer it for a rank holding none)
        columns = [part.gid.reshape(-1, 1)] + [a.reshape(a.shape[0], math.prod(a.shape[1:])) for a in arrays]
        widths = [c.shape[1] for c in columns]
        rows = [own[marks[rank]] for rank in range(size)]  # each rank's, in ascending global index
        send_counts = np.array([r.size for r in rows], dtype=np.int64)
        sending = np.empty((int(send_counts.sum()), sum(widths)))
        start = 0
        for local in rows:  # (compiled copies: the columns of each row, as doubles)
            first = 0
            for c in columns:
                rows_out(c, local, sending[start : start + local.size], first)
                first += c.shape[1]
            start += local.size
        receive_counts = np.empty(size, dtype=np.int64)
        comm.Alltoall(send_counts, receive_counts)
        arrived = np.empty((int(receive_counts.sum()), sum(widths)))
        comm.Alltoallv([sending, send_counts * sum(widths)], [arrived, receive_counts * sum(widths)])
        arrived = arrived[np.argsort(arrived[:, 0], kind="stable")]
        out, first = [], widths[0]
        for a, width in zip(arrays, widths[1:], strict=True):
            out.append(arrived[:, first : first + width].astype(a.dtype).reshape(-1, *a.shape[1:]))
            first += width
        return tuple(out)

    def _own(self) -> np.ndarray:
        """This rank's own particles (local indices, ascending); found once a list build (the
        owners change only there)."""
        part = self.part
        if part.own is None:
            part.own = np.flatnonzero(part.owned)
        return part.own

    def _stable(self) -> bool:
        """Collective: no rank's particles, and no rank's view of the fluid (its own arrays
        whole, the per-particle ones of the particles held: FluidModule.first_unstable), gone
        bad."""
        part = self.part
        state = part.state
        p, box = state.particles, state.box
        i, _ = first_unstable(
            p.pos, p.vel, p.angvel, p.radius, box.lower, box.upper, box.periodic, state.clock.dt
        )
        first = int(part.gid[i]) if i >= 0 else np.iinfo(np.int64).max
        if part.fluid is not None and part.fluid.first_unstable(state) is not None:
            first = -1
        return self.world.comm.allreduce(first, op=self.world.mpi.MIN) == np.iinfo(np.int64).max

    def _gather(self) -> list | None:
        """The owned particles of every rank, at the lead, as one pack in rank order (None
        elsewhere): each array's rows of every rank received straight into one array, an
        MPI_Gatherv of its bytes a name (a pickled gather of the packs copied every array three
        times more: 39 of 72 ms at 100 000 spheres on 2 ranks)."""
        part, world = self.part, self.world
        own = np.flatnonzero(part.owned)
        packed = _pack(
            part.state, part.gid, own, self.t.springs, part.state.neighbors.ref_pos, part.fluid, part.budget
        )
        names = sorted(packed)  # the same on every rank
        rows = np.array([packed[name].shape[0] for name in names], dtype=np.int64)
        every = np.empty((world.size, rows.size), dtype=np.int64) if world.leads else None
        world.comm.Gather(rows, every, root=0)
        out = {}
        for column, name in enumerate(names):
            mine = np.ascontiguousarray(packed[name])
            row_bytes = int(np.prod(mine.shape[1:])) * mine.itemsize
            received = None
            if world.leads:
                out[name] = np.empty((int(every[:, column].sum()), *mine.shape[1:]), dtype=mine.dtype)
                counts = every[:, column] * row_bytes
                received = [out[name], counts, np.cumsum(counts) - counts, world.mpi.BYTE]
            world.comm.Gatherv([mine, world.mpi.BYTE], received, root=0)
        return [out] if world.leads else None

    def _rebuild(self) -> None:
        """A list build, collective: ownership from the positions now, each own particle sent
        with its rows to the other ranks that own or hold it next, and this rank's new part made
        of those it keeps and those that came, its list built carrying their springs."""
        part, t, world = self.part, self.t, self.world
        state = part.state
        t.capacity = state.neighbors.nbr.shape[1]
        t.builds = state.neighbors.builds
        t.builds_since_growth = part.search.builds_since_growth
        t.step = state.clock.step
        if state.walls is not None:  # moving walls have moved since the last share
            t.walls = {name: getattr(state.walls, name) for name in WALL_FIELDS}
        own = np.flatnonzero(part.owned)
        pos = state.particles.pos
        held = [own[mine] for mine in self._cut_and_hold(pos[own])]
        outgoing = [
            {}
            if r == world.rank
            else _pack(state, part.gid, held[r], t.springs, pos, part.fluid, part.budget)
            for r in range(world.size)
        ]
        came = _merge(world.comm.alltoall(outgoing))
        rec = _assembled(part, held[world.rank], came, t.springs)
        self.part = self._make_part(rec, state.neighbors.moved2, build=True)
        self._plan_fluid()

    def _plan_fluid(self) -> None:
        """Collective, on every rank before its steps and after each list build: what the
        fluid's messages of a step need until the next build (FluidModule.plan_rank_steps)."""
        if self.part.fluid is not None:
            self.part.fluid.plan_rank_steps(self.part.state)

    def _share(self, packs: list) -> None:
        """Collective: the particles in `packs` (the whole scene at the lead, none elsewhere) go
        to the ranks that own or hold them by the cells of their `ref` positions, with their
        list; this rank's part is made of what it receives."""
        world = self.world
        mine = _merge(packs)  # empty: a follower before its first share (the lead sends all)
        held = self._cut_and_hold(mine["ref"] if mine else np.zeros((0, 3)))
        # what stays is neither pickled nor copied before the one copy below
        outgoing = [{} if r == world.rank else _select(mine, held[r]) for r in range(world.size)]
        arrived = world.comm.alltoall(outgoing)
        # this rank's particles in ascending global index: what stays and what arrived, each
        # array taken once from the pool of both
        pool = _merge([mine, *arrived])
        stays = mine["gid"].size if mine else 0
        take = np.concatenate([held[world.rank], np.arange(stays, pool["gid"].size)])
        take = take[np.argsort(pool["gid"][take], kind="stable")]
        self.part = self._make_part(_select(pool, take), 0.0, build=False)

    def _cut_and_hold(self, ref: np.ndarray) -> list[np.ndarray]:
        """Collective: the cut made again (`_cut`) from the positions `ref` this rank sends, and
        for each rank which of them it holds next (indices into ref, ascending)."""
        self._cut(ref)
        _, holders = self._owners(self._cut_cells(ref))
        return [np.flatnonzero((holders == r).any(axis=0)) for r in range(self.world.size)]

    def _cells(self, ref: np.ndarray, axis: int) -> np.ndarray:
        """Each position's search cell along `axis` (kernels/neighbors.py cell_number)."""
        t = self.t
        cell = np.floor((ref[:, axis] - t.lower[axis]) / t.cell[axis]).astype(np.int64)
        return np.clip(cell, 0, t.cells[axis] - 1)

    def _cut_cells(self, ref: np.ndarray) -> np.ndarray:
        """(k, n): each position's search cell along each of the k axes of the cut."""
        return np.stack([self._cells(ref, axis) for axis, _ in self.cut])

    def _owners(self, cells: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The rank owning each cell (n,), and the ranks holding a particle in it (3^k, n): the
        owners of that cell and of the cells next to it along the cut's k axes, diagonals
        included (-1 past an open end)."""
        shifts = itertools.product((-1, 0, 1), repeat=len(self.cut))
        holders = np.stack([self._owner_of_cell(cells + np.array(s)[:, None]) for s in shifts])
        return self._owner_of_cell(cells), holders

    def _owner_of_cell(self, cells: np.ndarray) -> np.ndarray:
        """The rank owning each cell of (k, n) along the cut's axes; a cell past an open end: -1."""
        owner = np.zeros(cells.shape[1], dtype=np.int64)
        outside = np.zeros(cells.shape[1], dtype=bool)
        for (axis, bounds), cell in zip(self.cut, cells, strict=True):
            count = self.t.cells[axis]
            if self.t.periodic[axis]:
                cell = cell % count
            outside |= (cell < 0) | (cell >= count)
            owner = owner * (bounds.size - 1) + np.searchsorted(bounds, cell, side="right") - 1
        return np.where(outside, -1, owner)

    def _cut(self, ref: np.ndarray) -> None:
        """The cut, from the positions `ref` this rank sends (the lead's whole scene at a share)
        and the particles of each cell counted over every rank: slabs along each axis that may
        be cut (`_slabs`), and pencils along each pair of them for each way of writing the rank
        count as a product of two (the slabs of each axis cut from its own counts); then the cut
        whose busiest rank holds the fewest particles, own and ghosts (the last cut's axes and
        parts unless another holds SWITCH_GAIN fewer; on a tie slabs before pencils, the lower
        axes first). With rank_balance =
        "time" each rank counts its particles by its force time per particle held since the last
        cut, so that the shares are of measured work (the first cut, before any step, by
        particles)."""
        t, size = self.t, self.world.size
        weight = 1.0
        if t.balance == "time" and self.part is not None and self.part.gid.size and self.busy > 0.0:
            weight = self.busy / self.part.gid.size
        self.busy = 0.0
        cells = {a: self._cells(ref, a) for a in t.axes}
        slabs_fit = any(t.cells[a] >= size for a in t.axes)
        pairs = [
            (a, b)
            for a, b in itertools.combinations(t.axes, 2)
            if _pencils(size, t.cells[a], t.cells[b])
            and (t.cells[a] * t.cells[b] <= PENCIL_GRID_CELLS or not slabs_fit)
        ]
        counts = [np.bincount(cells[a], minlength=t.cells[a]) * weight for a in t.axes]
        counts += [
            np.bincount(cells[a] * t.cells[b] + cells[b], minlength=t.cells[a] * t.cells[b]) * weight
            for a, b in pairs
        ]
        total = np.empty(sum(c.size for c in counts))
        self.world.comm.Allreduce(np.concatenate(counts), total, op=self.world.mpi.SUM)
        ends = np.cumsum([c.size for c in counts])
        along = {a: total[end - c.size : end] for a, c, end in zip(t.axes, counts, ends, strict=False)}
        candidates = [(a, along[a], size) for a in t.axes if t.cells[a] >= size]
        for (a, b), end in zip(pairs, ends[len(t.axes) :], strict=True):
            grid = total[end - t.cells[a] * t.cells[b] : end].reshape(t.cells[a], t.cells[b])
            candidates += [((a, b), grid, split) for split in _pencils(size, t.cells[a], t.cells[b])]
        best = None
        for axes, counted, parts in candidates:
            if isinstance(axes, tuple):  # pencils: parts = (along a, along b)
                a, b = axes
                cut = tuple(
                    (axis, _slabs(along[axis], p, t.periodic[axis])[0])
                    for axis, p in zip(axes, parts, strict=True)
                )
                largest = max(_held_in_block(counted, cut, t.periodic[[a, b]], r) for r in range(size))
            else:
                bounds, largest = _slabs(counted, parts, t.periodic[axes])
                cut = ((axes, bounds),)
            same = [(axis, b.size) for axis, b in cut] == [(axis, b.size) for axis, b in self.cut]
            score = largest if same else largest * (1.0 + SWITCH_GAIN)
            if best is None or score < best[0]:
                best = (score, cut)
        self.cut = best[1]

    def _make_part(self, rec: dict, moved2: float, build: bool) -> Part:
        """This rank's part of the particles of `rec` (a pack: _pack, _select, _assembled), its
        list taken from their rows, or, where `build`, built from their positions (`moved2`:
        the displacement it is built for)."""
        t, world = self.t, self.world
        n = rec["gid"].size
        owned = self._owner_of_cell(self._cut_cells(rec["ref"])) == world.rank
        particles = Particles(**{name: rec[name] for name in CARRIED})
        nbr = np.zeros((n, t.capacity), dtype=np.int32)
        count = np.zeros(n, dtype=np.int32)
        start = np.zeros(n + 1, dtype=np.int64)
        hist = np.zeros((0, 3))
        if not build:
            # each row's partners by local index, those this rank does not hold left out (they
            # lie beyond the ghosts: out of reach of every particle here), and the pairs of two
            # ghosts
            row_start = np.zeros(n + 1, dtype=np.int64)
            np.cumsum(rec["row_count"], out=row_start[1:])
            where = np.empty(row_start[-1], dtype=np.int64)
            local_partners(rec["gid"], row_start, rec["partner"], where, count)
            row_starts(count, t.capacity, start)
            hist = np.zeros((int(SPRING_ROOM * start[-1]) + 64, 3) if t.springs else (0, 3))
            fill_rows(row_start, where, rec.get("spring", hist), t.springs, start, nbr, hist, np.arange(n))
            drop_ghost_pairs(owned, nbr, count, start, hist, t.springs)
        nl = NeighborList(
            skin=t.skin,
            nbr=nbr,
            nbr_count=count,
            start=start,
            hist=hist,
            ref_pos=np.ascontiguousarray(rec["ref"]),
            rev=np.zeros((n, t.capacity), dtype=np.int32),
            rev_count=np.zeros(n, dtype=np.int32),
            builds=t.builds,
            moved2=moved2,
        )
        walls = None
        # the glued spheres held here, and their places in the lead's list
        where = np.minimum(np.searchsorted(rec["gid"], t.attached), max(n - 1, 0))
        present = rec["gid"][where] == t.attached if n else np.zeros(t.attached.size, dtype=bool)
        glued, glued_order = where[present], np.flatnonzero(present)
        if t.walls is not None:
            nw = len(t.walls["faces"])
            walls = Walls(
                **{name: (list(v) if name == "faces" else np.array(v)) for name, v in t.walls.items()},
                hist=np.ascontiguousarray(rec["wall_hist"]) if t.springs else np.zeros((0, nw, 3)),
                attached=glued.astype(np.int64),
                attached_wall=t.attached_wall[glued_order],
                pforce=np.zeros((n if t.moving else 0, nw, 3)),
            )
        clock = Clock(dt=t.dt, step=t.step)
        state = State(clock=clock, box=t.box, particles=particles, neighbors=nl, walls=walls)
        fluid = None
        if t.fluid is not None:  # its particles' arrays those received
            fluid = self._fluid_for(state, lambda name, _: rec[FLUID + name])
        search = NeighborSearch(state, t.springs)
        search.builds_since_growth = t.builds_since_growth
        search.longest = self._longest
        if build:  # the springs carried from the rows received (collective: the rows' width)
            received = (
                rec["gid"],
                rec["row_first"],
                rec["row_count"],
                rec["partner"],
                rec.get("spring", hist),
            )
            search.rebuild(state, received, owned)
        else:
            NeighborSearch._reverse(nl)
        contact = PairContactForces(t.tables)
        contact.table[...] = t.table  # the friction of the stage under way
        plane_walls = None if walls is None else PlaneWallForces(contact)
        budget = None
        if t.budget:  # what it reads of a scene, the part's; each particle's share received
            held = types.SimpleNamespace(state=state, contact=contact, walls=plane_walls)
            budget = EnergyBudget(held, booked=np.ascontiguousarray(rec["budget"]))
        part = Part(
            gid=rec["gid"],
            owned=owned,
            state=state,
            search=search,
            contact=contact,
            walls=plane_walls,
            wall_motion=WallMotion() if t.moving else None,
            fluid=fluid,
            budget=budget,
            glued=glued,
            glued_order=glued_order,
            send={},
            receive={},
        )
        self._exchange_lists(part)
        return part

    def _longest(self, needed: int) -> int:
        """The longest row over every rank (each rank's rows then widen and narrow alike)."""
        return self.world.comm.allreduce(needed, op=self.world.mpi.MAX)

    def _exchange_lists(self, part: Part) -> None:
        """Which own particles each rank holds as ghosts, and which ghosts each rank owns, both
        in ascending global index (each side derives the other's list from the same cells)."""
        owner, holders = self._owners(self._cut_cells(part.state.neighbors.ref_pos))
        part.send, part.receive = {}, {}
        for rank in range(self.world.size):
            if rank == self.world.rank:
                continue
            send = np.flatnonzero(part.owned & (holders == rank).any(axis=0))
            receive = np.flatnonzero(owner == rank)
            if send.size:
                part.send[rank] = send
            if receive.size:
                part.receive[rank] = receive


def _ghost_rows(part: Part) -> list[np.ndarray]:
    """What an owner sends of each of its particles that is a ghost elsewhere, after the step's
    forces: force, torque and the fluid's ghost_arrays, each (n, k). The compiled loops send the
    same rows (kernels/rank_messages.py send_ghost_forces), so that a rank stepping from Python
    and one stepping in a compiled call exchange messages of one size."""
    p = part.state.particles
    sent = [p.force, p.torque]
    if part.fluid is not None:
        arrays = part.fluid.particle_arrays(part.state)
        for name in part.fluid.ghost_arrays():
            holder, attribute = arrays[name]
            sent.append(getattr(holder, attribute))
    return sent


def _slabs(total: np.ndarray, size: int, periodic: bool) -> tuple[np.ndarray, float]:
    """Slab boundaries along one axis where each of `size` ranks holds about as many particles
    (or work) of `total` (per cell), its ghosts counted, each slab at least one cell wide: cuts
    nearest the even shares, then each moved by a cell where that lowers the larger of the two
    slabs it bounds; and what the busiest rank then holds."""
    cells = total.size
    work = np.concatenate(([0], np.cumsum(total)))  # particles (or work) in cells [0, c)
    targets = np.arange(1, size) * (work[-1] / size)
    above = np.clip(np.searchsorted(work, targets), 1, cells - 1)
    below_is_nearer = np.abs(work[above - 1] - targets) <= np.abs(work[above] - targets)
    nearer = np.where(below_is_nearer, above - 1, above)
    k = np.arange(1, size)
    cuts = np.maximum.accumulate(np.maximum(nearer, k) - k) + k  # each slab a cell or more
    cuts = np.minimum(cuts, cells - size + k)
    slabs = np.concatenate(([0], cuts, [cells])).astype(np.int64)
    for k in range(1, size):
        best = _held(total, slabs, k, periodic)
        for shift in (-1, 1):
            trial = slabs.copy()
            trial[k] += shift
            if trial[k - 1] < trial[k] < trial[k + 1] and _held(total, trial, k, periodic) < best:
                slabs, best = trial, _held(total, trial, k, periodic)
    return slabs, max(_held_by(total, slabs, r, periodic) for r in range(size))


def _pencils(size: int, cells_a: int, cells_b: int) -> list[tuple[int, int]]:
    """The ways of cutting `size` ranks into pencils p_a x p_b, each at least 2, each axis with
    a cell for each of its parts."""
    return [
        (p, size // p)
        for p in range(2, size // 2 + 1)
        if size % p == 0 and p <= cells_a and size // p <= cells_b
    ]


def _held_in_block(grid: np.ndarray, cut: tuple, periodic: np.ndarray, r: int) -> float:
    """The particles (or work) of grid (cells along a, cells along b) that rank r of the
    pencils `cut` holds: its block and the cells next to it, diagonals included (a cell once
    however it wraps)."""
    index = []
    for (_, bounds), count, wraps, part in zip(
        cut, grid.shape, periodic, divmod(r, cut[1][1].size - 1), strict=True
    ):
        near = np.arange(bounds[part] - 1, bounds[part + 1] + 1)
        near = np.unique(near % count) if wraps else near[(near >= 0) & (near < count)]
        index.append(near)
    return float(grid[np.ix_(*index)].sum())


def _held_by(counts: np.ndarray, slabs: np.ndarray, r: int, periodic: bool) -> float:
    """The particles (or work) rank r holds, own and ghosts."""
    cells = counts.size
    first, end = slabs[r], slabs[r + 1]
    ghosts = [first - 1, end]
    if periodic:
        ghosts = [c % cells for c in ghosts]
    return float(counts[first:end].sum()) + sum(float(counts[c]) for c in ghosts if 0 <= c < cells)


def _held(counts: np.ndarray, slabs: np.ndarray, k: int, periodic: bool) -> float:
    """The larger of the particles (or work) held, own and ghosts, by the two slabs that cut k
    bounds."""
    return max(_held_by(counts, slabs, k - 1, periodic), _held_by(counts, slabs, k, periodic))


def _pack(
    state: State, gid: np.ndarray, idx: np.ndarray, springs: bool, ref: np.ndarray, fluid, budget
) -> dict:
    """The particles `idx` of a state (global indices gid[idx]) with their half rows by global
    index, their springs, the fluid's arrays of them and their shares of the energy budget:
    what a rank sends of them."""
    rec = {name: array[idx] for name, array in _carried(state, springs, fluid, budget).items()}
    rec["gid"] = gid[idx].astype(np.int64)
    rec["ref"] = ref[idx]
    rec["row_count"], rec["partner"], spring = _half_rows(state, gid, idx, springs)
    if springs:
        rec["spring"] = spring
    return rec


def _carried(state: State, springs: bool, fluid, budget) -> dict:
    """{name in a pack: the state's array} of what travels with a particle besides its rows:
    CARRIED, its wall springs, the fluid's arrays of it and its share of the energy budget."""
    arrays = {name: getattr(state.particles, name) for name in CARRIED}
    if springs and state.walls is not None:
        arrays["wall_hist"] = state.walls.hist
    if fluid is not None:
        for name, (holder, attribute) in fluid.particle_arrays(state).items():
            arrays[FLUID + name] = getattr(holder, attribute)
    if budget is not None:
        arrays["budget"] = budget.booked
    return arrays


def _half_rows(state: State, gid: np.ndarray, idx: np.ndarray, springs: bool) -> tuple:
    """The half rows of the particles idx by global index: each row's length, the partners
    one row after the other, and (springs) their springs in the same places."""
    nl = state.neighbors
    count = np.minimum(nl.nbr_count[idx], nl.nbr.shape[1]).astype(np.int64)
    row_start = np.zeros(idx.size + 1, dtype=np.int64)
    np.cumsum(count, out=row_start[1:])
    partner = np.empty(row_start[-1], dtype=np.int64)
    spring = np.empty((row_start[-1] if springs else 0, 3))
    rows_by_global_index(
        idx, gid, nl.nbr, nl.nbr_count, nl.start, nl.hist, springs, row_start, partner, spring
    )
    return count, partner, spring


def _merge(packs: list) -> dict:
    """One pack of several (in the order given)."""
    packs = [p for p in packs if p]
    if not packs:
        return {}
    if len(packs) == 1:  # not copied: every caller reads it
        return packs[0]
    return {name: np.concatenate([p[name] for p in packs]) for name in packs[0]}


def _select(rec: dict, idx: np.ndarray) -> dict:
    """The particles idx of a pack, their rows with them."""
    if not rec:
        return {}
    rows = _rows(rec["row_count"], idx)
    out = {}
    for name, value in rec.items():
        out[name] = value[rows] if name in ("partner", "spring") else value[idx]
    return out


def _assembled(part: Part, keep: np.ndarray, came: dict, springs: bool) -> dict:
    """The pack of a rank's particles after a list build, in global order: those of its part it
    keeps (local indices `keep`, its own) and those that `came` (a pack), each array copied once
    (merge_rows); the rows stay where they are, found by "row_first" (their order in "partner"
    and "spring" is the kept ones', then those that came)."""
    state = part.state
    gid = np.concatenate([part.gid[keep], came["gid"] if came else np.zeros(0, dtype=np.int64)])
    source = np.argsort(gid, kind="stable")
    rec = {"gid": gid[source]}
    for name, array in _carried(state, springs, part.fluid, part.budget).items():
        width = math.prod(array.shape[1:])
        out = np.empty((source.size, *array.shape[1:]), dtype=array.dtype)
        arrived = came[name] if came else array[:0]
        merge_rows(
            array.reshape(-1, width),
            keep,
            arrived.reshape(len(arrived), width),
            source,
            out.reshape(-1, width),
        )
        rec[name] = out
    rec["ref"] = rec["pos"].copy()
    count, partner, spring = _half_rows(state, part.gid, keep, springs)
    if came:
        count = np.concatenate([count, came["row_count"]])
        partner = np.concatenate([partner, came["partner"]])
        if springs:
            spring = np.concatenate([spring, came["spring"]])
    rec["row_first"] = (np.cumsum(count) - count)[source]
    rec["row_count"] = count[source]
    rec["partner"] = partner
    if springs:
        rec["spring"] = spring
    return rec


def _rows(row_count: np.ndarray, idx: np.ndarray) -> np.ndarray:
    """The entries of a pack's concatenated rows (partner, spring) that belong to its particles
    idx, in that order."""
    first = np.cumsum(row_count) - row_count
    counts = row_count[idx]
    before = np.cumsum(counts) - counts
    return np.arange(int(counts.sum())) - np.repeat(before, counts) + np.repeat(first[idx], counts)


def _unpack_into_host(state: State, packs: list, capacity: int, springs: bool, fluid, budget) -> None:
    """The gathered owners' particles into the lead's whole scene (its list in one rank's layout),
    each row placed by its global index in one compiled pass (rows_in, fill_rows)."""
    rec = _merge(packs)
    gid = rec["gid"]
    nl = state.neighbors
    # the scene's per-particle arrays are C-contiguous (the kernels' flat views need it), so
    # each reshaped is a view of it
    for name, target in {**_carried(state, springs, fluid, budget), "ref": nl.ref_pos}.items():
        width = math.prod(target.shape[1:])
        rows_in(rec[name].reshape(len(gid), width), gid, target.reshape(-1, width), 0)
    n = state.particles.count
    nl.nbr = np.zeros((n, capacity), dtype=np.int32)
    nl.nbr_count = np.zeros(n, dtype=np.int32)
    nl.nbr_count[gid] = rec["row_count"]
    nl.start = np.zeros(n + 1, dtype=np.int64)
    row_starts(nl.nbr_count, capacity, nl.start)
    if springs:
        nl.hist = np.zeros((int(SPRING_ROOM * nl.start[-1]) + 64, 3))
    row_start = np.zeros(len(gid) + 1, dtype=np.int64)
    np.cumsum(rec["row_count"], out=row_start[1:])
    spring = rec.get("spring", nl.hist)
    fill_rows(row_start, rec["partner"], spring, springs, nl.start, nl.nbr, nl.hist, gid)
    nl.rev = np.zeros((n, capacity), dtype=np.int32)
    NeighborSearch._reverse(nl)
