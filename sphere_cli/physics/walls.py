"""Plane walls on the box faces: their contact with particles (the forces hook) and their motion
(kick_drift and kick), with kernels/walls.py and the wall rows of the parameter tables
(physics/materials.py).

Modes, per wall and per stage (physics/stages.py): fixed; prescribed normal velocity; normal
stress control, optionally modulated by a sine; and, on any of these, a tangential drive at a
prescribed shear velocity or shear stress. A driven direction obeys (kernels/walls.py)
    M dV/dt = A target + F - C V
(F: the particles' force on the wall along that direction, A: the wall's current area), so it
comes to rest where the contact stress equals the target. Defaults that scale with the scene:
    M = m_mean A / d_mean^2            one layer of mean particles covering the wall,
    K_1 = k A / d_mean^2               one layer of contacts of stiffness k in parallel,
    K_bed = K_1 / L                    L = H/d_mean such layers in series, H the distance to
                                       the opposite wall (or face) when the mode is set,
    C = damping 2 sqrt(K_bed M)        critical (damping = 1) against that bed,
with m_mean, d_mean over the free particles and k the wall contact's normal stiffness (for the
Hertz law its tangent stiffness 2 E* sqrt(r delta) at delta = max(overlap_tolerance, 1 %) of
the mean radius). The wall then settles on the bed in about 2 sqrt(M/K_bed) =
2 sqrt(L m_mean/k) without ringing (a softer bed overdamps it, a stiffer one rings a little).
Where nothing resists it moves at A sigma/C. The stiffest load it can meet is K_1, undamped
frequency sqrt(K_1/M) = sqrt(k/m_mean), that of one contact; the damping is implicit, so a
driven wall does not tighten the time step (its limit 2/omega against K_1 is checked anyway).

A rough wall carries a square lattice of spheres glued to it, centres on its plane: particles
with inv_mass = 0 whose velocity is set to the wall's every step; the contact forces on them
count as force on the wall. Each wall has its own mode: no wall's force enters another's
motion (their areas follow each other's positions).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from ..kernels.contact import BLOCK, FIELDS
from ..kernels.exact_sum import WORDS
from ..kernels.observe.energy import wall_elastic_energy
from ..kernels.serial import use_serial
from ..kernels.walls import (
    C_AMPLITUDE,
    C_DAMPING,
    C_MASS,
    C_OMEGA,
    C_PHASE,
    C_SHEAR,
    C_SHEAR_AXIS,
    C_START,
    C_STRESS,
    C_VELOCITY,
    FIXED,
    NEAR,
    PIECES,
    STRESS,
    VELOCITY,
    listed_wall_totals,
    near_walls,
    spring_bits,
    wall_areas,
    wall_forces,
    wall_forces_serial,
    wall_kick,
    wall_kick_drift,
    wall_totals,
)
from ..state import State, Walls
from .contact import verlet_limit
from .module import Module

AXES = {"x": 0, "y": 1, "z": 2}
MODES = {"fixed": FIXED, "velocity": VELOCITY, "stress": STRESS}

WALL_UNITS = {
    "wall_position": "m",
    "wall_velocity": "m s-1",
    "wall_force": "N",
    "wall_normal_stress": "Pa",
    "wall_shear_stress": "Pa",
}


class WallScales:
    """Mass, stiffness and damping of driven walls per unit area, from the free particles."""

    def __init__(self, case, tables, radius, mass, inv_mass):
        free = inv_mass > 0.0
        if not np.any(free):
            free = np.ones_like(inv_mass, dtype=bool)
        self.diameter = float((2.0 * radius[free]).mean())
        self.mass_per_area = float(mass[free].mean()) / self.diameter**2
        d2 = self.diameter**2
        stiffness = []
        r_mean = float(radius[free].mean())
        delta = max(case.particles.overlap_tolerance, 0.01) * r_mean
        for w in range(tables.wall_table.shape[0]):
            row = tables.wall_table[w, 0]
            stiffness.append(tables.law.normal_stiffness(row, r_mean, delta) / d2)
        self.stiffness_per_area = np.array(stiffness)

    def mass(self, spec, area: float) -> float:
        return spec.mass if spec.mass is not None else self.mass_per_area * area

    def damping(self, spec, w: int, area: float, height: float) -> float:
        """C [kg/s]: `damping` times critical against a bed of `height` [m] between the wall and
        the opposite one, taken as height/d_mean layers of one-layer stiffness in series."""
        ratio = 1.0 if spec.damping is None else spec.damping
        layers = max(1.0, height / self.diameter)
        return ratio * 2.0 * math.sqrt(self.stiffness_per_area[w] * area / layers * self.mass(spec, area))

    def dt_limit(self, spec, w: int, area: float, fluid: float = 0.0) -> float:
        """Stability limit [s] of a driven wall against one layer of contacts and the stiffness
        `fluid` [N/m] of a pore fluid pushing it (in parallel): 2/omega (its damping is
        implicit, kernels/walls.py)."""
        return verlet_limit(self.stiffness_per_area[w] * area + fluid, 0.0, 0.0, self.mass(spec, area))


def wall_sums(walls: Walls) -> np.ndarray:
    """The words of the exact sums of the forces on the walls (kernels/walls.py wall_totals),
    made once."""
    if walls.sums is None:
        walls.sums = np.zeros((len(walls.faces), 3, WORDS), dtype=np.int64)
    return walls.sums


def bed_height(walls: Walls, w: int, coord, box) -> float:
    """Distance [m] from wall w to the opposite wall (or the opposite face of the box)."""
    a = walls.axis[w]
    opposite = [k for k in range(len(walls.faces)) if walls.axis[k] == a and k != w]
    if opposite:
        return abs(float(coord[w] - coord[opposite[0]]))
    far = box.upper[a] if walls.sign[w] > 0 else box.lower[a]
    return abs(float(coord[w] - far))


def apply_modes(walls: Walls, specs: dict, scales: WallScales, box, start_time: float, coord) -> None:
    """Set the mode of the walls in `specs` (wall index -> WallMotion) from `start_time` [s];
    default masses and damping follow the wall areas at the wall positions `coord` (W,) [m] of
    that time."""
    coord = np.asarray(coord, dtype=np.float64)
    area = np.zeros(len(walls.faces))
    wall_areas(walls.axis, walls.sign, coord, box.lower, box.upper, area)
    for w, spec in specs.items():
        c = walls.control[w]
        c[:] = 0.0
        walls.mode[w, 0] = MODES[spec.mode]
        c[C_VELOCITY] = spec.velocity or 0.0
        c[C_STRESS] = spec.stress or 0.0
        if spec.stress_amplitude is not None:
            c[C_AMPLITUDE] = spec.stress_amplitude
            c[C_OMEGA] = 2.0 * math.pi * spec.frequency
            c[C_PHASE] = spec.phase or 0.0
        walls.mode[w, 1] = FIXED
        c[C_SHEAR_AXIS] = (walls.axis[w] + 1) % 3
        if spec.shear_axis is not None:
            c[C_SHEAR_AXIS] = AXES[spec.shear_axis]
            walls.mode[w, 1] = VELOCITY if spec.shear_velocity is not None else STRESS
            c[C_SHEAR] = spec.shear_velocity if spec.shear_velocity is not None else spec.shear_stress
        c[C_MASS] = scales.mass(spec, area[w])
        c[C_DAMPING] = (
            scales.damping(spec, w, area[w], bed_height(walls, w, coord, box)) if spec.driven else 0.0
        )
        c[C_START] = start_time
        walls.record[w] = walls.mode[w, 0] != FIXED or walls.mode[w, 1] != FIXED


class PlaneWallForces(Module):
    name = "walls"

    def __init__(self, contact):
        self.contact = contact  # shares the law (linear or Hertz) and the rolling switch
        self._springs = None  # which wall springs may be set, per particle (kernels/walls.py)
        self._springs_of = None  # the hist array that mask describes
        # the particles that can touch a wall (kernels/walls.py near_walls), valid while no
        # particle has moved half the neighbour skin since the neighbour list was built (the
        # list is rebuilt with it) and no wall has moved half the skin since this list was made
        self._near = np.zeros(0, dtype=np.int64)
        self._reach = np.zeros(0, dtype=np.uint64)  # per listed particle, the walls it can touch
        # per particle, those and the walls whose springs the list's making cleared
        self._to_book = np.zeros(0, dtype=np.uint64)
        self._near_count = 0
        self._near_build = -1
        self._near_coord = None
        # per thread, a block of wall contacts whose law is evaluated in one vectorised loop
        # (kernels/contact.py, kernels/walls.py)
        self._blocks = np.zeros((0, FIELDS * BLOCK))
        self._block_ids = np.zeros((0, 2 * BLOCK), dtype=np.uint64)
        self._pieces = np.zeros(2, dtype=np.int64)  # the near list cut into one piece per thread

    def scratch(self) -> list[np.ndarray]:
        """The arrays this module keeps besides the state (memory accounting)."""
        return [
            a
            for a in (self._near, self._reach, self._to_book, self._springs, self._blocks, self._block_ids)
            if a is not None
        ]

    def _spring_mask(self, hist: np.ndarray, n: int) -> np.ndarray:
        """The bit mask of possibly non-zero springs of `hist` for the n particles, derived again
        whenever the state's hist is a new array (start, restore); none without friction (hist
        has no rows). A spring of -0.0 counts as set, as it is in the run that set it: the end of
        its contact then clears it to +0.0 there too (a resumed run stays bitwise)."""
        if self._springs_of is not hist:
            self._springs = np.zeros(n, dtype=np.uint64)
            if hist.shape[0]:
                spring_bits(hist, self._springs)
            self._springs_of = hist
            self._near_build = -1
        return self._springs

    def _near_walls(self, state: State, springs: np.ndarray) -> np.ndarray:
        p, w, nl = state.particles, state.walls, state.neighbors
        if (
            self._near_build != nl.builds
            or self._near_coord is None
            or (
                w.coord.tobytes() != self._near_coord.tobytes()  # cheaper than the test below
                and np.abs(w.coord - self._near_coord).max(initial=0.0) >= 0.5 * nl.skin
            )
        ):
            if self._near.shape[0] != p.count:
                self._near = np.zeros(p.count, dtype=np.int64)
                self._reach = np.zeros(p.count, dtype=np.uint64)
                self._to_book = np.zeros(p.count, dtype=np.uint64)
            self._near_count = near_walls(
                p.pos,
                p.radius,
                p.inv_mass,
                w.axis,
                w.sign,
                w.coord,
                nl.skin,
                springs,
                w.hist,
                self._near,
                self._reach,
                self._to_book,
            )
            self._near_build = nl.builds
            self._near_coord = w.coord.copy()
            self._pieces = self._cut(self._near[: self._near_count], w.hist)
            if w.pforce.shape[0]:
                w.pforce[...] = 0.0  # only listed particles are written from now on
            w.listed = self._near[: self._near_count]
        elif self._pieces.size != numba.get_num_threads() + 1:
            self._pieces = self._cut(self._near[: self._near_count], w.hist)
        return self._near[: self._near_count]

    def walls_to_book(self) -> np.ndarray:
        """(N,) uint64: per particle, the bit mask of the walls the energy budget must book for
        it until the near-wall list is made again (kernels/walls.py near_walls: those it can
        touch, and those whose spring the list's making cleared); empty before the first forces.
        Any other wall neither touches it nor holds a spring of it, then or at the last step."""
        return self._to_book

    def near_list_made_at(self, state: State) -> tuple[np.ndarray, float]:
        """The wall positions the near-wall list was made at, and how far [m] a wall may move
        from them before it is made again (half the neighbour skin; for kernels/steps.py)."""
        return self._near_coord, 0.5 * state.neighbors.skin

    def _threads_blocks(self) -> None:
        threads = numba.get_num_threads()
        if self._blocks.shape[0] != threads:
            self._blocks = np.zeros((threads, FIELDS * BLOCK))
            self._block_ids = np.zeros((threads, 2 * BLOCK), dtype=np.uint64)

    @staticmethod
    def _cut(near: np.ndarray, hist: np.ndarray) -> np.ndarray:
        """Cuts of `near` into one piece per thread with about as much work. The work of a listed
        particle is one unit, one more per touching wall (spring set), and four more when it
        lies over two places past the previous listed particle: then its (N,3) rows share no
        cache line with that one's and come from memory (the side walls' particles, scattered
        through the index range, against the floor's contiguous layer). Measured on the
        settled canonical beds, two threads: the wall time 87 -> 72 us at 10 000, 438 -> 350 us
        at 100 000 against touching walls weighted 4 and no memory term (docs/performance.md)."""
        threads = numba.get_num_threads()
        touching = np.count_nonzero(np.any(hist[near] != 0.0, axis=2), axis=1) if hist.shape[0] else 0
        isolated = np.diff(near, prepend=near[:1] - 3) > 2
        work = np.cumsum(1 + touching + 4 * isolated)
        total = work[-1] if work.size else 0
        cuts = np.searchsorted(work, np.arange(1, threads) * (total / threads))
        return np.concatenate(([0], cuts, [near.size])).astype(np.int64)

    def forces(self, state: State, spring_dt: float | None = None) -> None:
        kernel = wall_forces_serial if use_serial() else wall_forces
        kernel(*self.kernel_arguments(state, spring_dt))

    def kernel_arguments(self, state: State, spring_dt: float | None = None) -> tuple:
        """The arguments of wall_forces (kernels/walls.py; also for kernels/steps.py), valid
        while the neighbour list, the walls' positions and the thread count stay as they are."""
        hist = state.walls.hist
        springs = self._spring_mask(hist, state.particles.count)
        near = self._near_walls(state, springs)
        p = state.particles
        return self._arguments(
            state, spring_dt, hist, p.force, p.torque, springs, near, self._reach, self._pieces
        )

    @staticmethod
    def by_chunks(arguments: tuple, bounds: np.ndarray) -> tuple:
        """wall_forces's arguments (kernel_arguments's) with the particles near the walls cut
        into one piece per chunk of the pair sweep (bounds: its chunks of particles), for
        kernels/steps.py chunk_steps_end, which takes each chunk's walls after its pairs."""
        pieces = arguments[PIECES]
        near = arguments[NEAR][: pieces[-1]]  # (ascending)
        cut = np.searchsorted(near, bounds).astype(np.int64)
        return arguments[:PIECES] + (cut,) + arguments[PIECES + 1 :]

    def argument_example(self, state: State) -> tuple:
        """Arguments of wall_forces of the types kernel_arguments gives, made without listing
        the particles near the walls (sphere_cli/compile_ahead.py compiles from their types)."""
        hist = state.walls.hist
        springs = np.zeros(state.particles.count, dtype=np.uint64)
        p = state.particles
        return self._arguments(
            state, None, hist, p.force, p.torque, springs, self._near, self._reach, self._pieces
        )

    def _arguments(
        self,
        state: State,
        spring_dt,
        hist,
        force,
        torque,
        springs,
        near,
        reach,
        pieces,
        record=None,
        pforce=None,
    ) -> tuple:
        p, w, c = state.particles, state.walls, self.contact
        dt = state.clock.dt
        self._threads_blocks()
        return (
            p.pos,
            p.vel,
            p.angvel,
            p.vel_pred,
            p.angvel_pred,
            p.radius,
            p.mass,
            p.inertia,
            p.inv_mass,
            p.material,
            w.axis,
            w.sign,
            w.coord,
            w.vel,
            w.vel_pred,
            w.table,
            hist,
            c.law_code,
            c.rolling,
            dt if spring_dt is None else spring_dt,
            dt,
            force,
            torque,
            w.record if record is None else record,
            w.pforce if pforce is None else pforce,
            springs,
            near,
            reach,
            pieces,
            self._blocks,
            self._block_ids,
            c.warm,
        )

    def measure(self, state: State) -> None:
        """Refresh walls.force (every wall) and walls.area at the current state. A step records
        the particles' forces on moving walls only, so they are recomputed here (same positions,
        velocities and springs, the springs not grown: spring_dt = 0, the force the step had)
        without touching the state."""
        p, w = state.particles, state.walls
        wall_areas(w.axis, w.sign, w.coord, state.box.lower, state.box.upper, w.area)
        every = np.ones(len(w.faces), dtype=np.uint8)
        pforce = np.zeros((p.count, len(w.faces), 3))
        scratch = np.zeros_like(p.force)
        hist = w.hist.copy()
        every_wall = np.full(p.count, ~np.uint64(0), dtype=np.uint64)
        springs = every_wall.copy()  # check every spring
        everyone = np.arange(p.count, dtype=np.int64)
        pieces = self._cut(everyone, hist)
        (wall_forces_serial if use_serial() else wall_forces)(
            *self._arguments(
                state,
                0.0,
                hist,
                scratch,
                scratch.copy(),
                springs,
                everyone,
                every_wall,
                pieces,
                every,
                pforce,
            )
        )
        wall_totals(
            pforce,
            every,
            wall_sums(w),
            w.attached,
            w.attached_wall,
            p.force,
            p.mass,
            state.box.body_acc,
            w.fluid_force,
            w.force,
        )

    def observables(self, state: State) -> dict:
        """Wall positions, velocities, forces and stresses (compressive normal stress; shear
        traction of the wall on the particles), per wall in the order of [[walls]]."""
        self.measure(state)
        w = state.walls
        normal = np.zeros((len(w.faces), 3))
        normal[np.arange(len(w.faces)), w.axis] = w.sign
        inward = np.einsum("wb,wb->w", w.force, normal)
        traction = -w.force / w.area[:, None]
        shear = traction + (inward / w.area)[:, None] * normal
        values = {
            "wall_position": w.coord.copy(),
            "wall_velocity": w.vel.copy(),
            "wall_force": w.force.copy(),
            "wall_normal_stress": -inward / w.area,
            "wall_shear_stress": shear,
        }
        return {name: (value, WALL_UNITS[name]) for name, value in values.items()}

    def elastic_energy(self, state: State) -> tuple[float, int]:
        p, w, c = state.particles, state.walls, self.contact
        energy, touching = wall_elastic_energy(
            p.pos, p.radius, p.inv_mass, p.material, w.axis, w.sign, w.coord, w.table, w.hist, c.law_code
        )
        return float(energy), int(touching)

    @staticmethod
    def prognostic_state(state: State) -> dict:
        walls = state.walls
        # the wall springs only when some contact has friction (hist has rows)
        kept = [name for name in Walls.PROGNOSTIC if name != "hist" or walls.hist.shape[0]]
        return {name: getattr(walls, name) for name in kept}

    @staticmethod
    def restore(state: State, arrays: dict) -> None:
        for name in Walls.PROGNOSTIC:
            if name != "hist" or state.walls.hist.shape[0]:  # springs only with friction
                setattr(state.walls, name, np.array(arrays[name], dtype=getattr(state.walls, name).dtype))


class WallMotion(Module):
    """Moves the walls: in the scene only if some wall moves in some stage."""

    name = "wall_motion"

    @staticmethod
    def kernel_arguments(state: State) -> tuple:
        """The arguments of wall_kick_drift, wall_areas, wall_totals (listed_wall_totals's after
        walls.listed) and of wall_kick but its time and dt (kernels/walls.py; also for
        kernels/steps.py)."""
        w, p, box = state.walls, state.particles, state.box
        return (
            (w.axis, w.sign, w.mode, w.control, w.coord, w.vel, w.acc, w.vel_pred, w.shift, state.clock.dt,
             w.attached, w.attached_wall, p.vel),
            (w.axis, w.sign, w.coord, box.lower, box.upper, w.area),
            (w.pforce, w.record, wall_sums(w), w.attached, w.attached_wall, p.force, p.mass,
             box.body_acc, w.fluid_force, w.force),
            (w.axis, w.sign, w.mode, w.control, w.force, w.area, w.vel, w.acc),
        )  # fmt: skip

    def kick_drift(self, state: State) -> None:
        wall_kick_drift(*self.kernel_arguments(state)[0])

    def kick(self, state: State) -> None:
        _, areas, totals, kick = self.kernel_arguments(state)
        wall_areas(*areas)
        listed_wall_totals(state.walls.listed, *totals)
        dt = state.clock.dt
        wall_kick(*kick, (state.clock.step + 1) * dt, dt)
