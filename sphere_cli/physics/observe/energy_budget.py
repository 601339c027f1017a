"""Energy budget (the forces and finish_step hooks, every step, only when `energy_budget` is
among the observables): work of gravity and of moving walls, and the energy dissipated by
damping, friction and rolling resistance, accumulated by kernels/observe/energy_budget.py before the
contact forces of each step.

The balance reported with the observables, against the energies at the start of accounting
(the start of the run, or the resume step if an older checkpoint had no budget):
    residual = W_gravity + W_walls - Delta(kinetic + elastic) - (damping + friction + rolling).
"""

from __future__ import annotations

import numpy as np

from ...kernels.observe.energy import kinetic_energy
from ...kernels.observe.energy_budget import (
    DAMPING,
    FRICTION,
    GRAVITY,
    ROLLING,
    TERMS,
    WALLS,
    accumulate_budget,
    accumulate_budget_serial,
    budget_totals,
    keep_half_step,
)
from ...kernels.serial import use_serial
from ...state import State
from ..module import Module

UNITS = {
    "work_gravity": "J",
    "work_walls": "J",
    "dissipated_damping": "J",
    "dissipated_friction": "J",
    "dissipated_rolling": "J",
    "energy_change": "J",
    "energy_balance_residual": "J",
}


class EnergyBudget(Module):
    """Two hooks per step: `forces` (before the contacts, physics/module.py ORDER) keeps the
    springs of the previous step and the half-step velocities; `finish_step` (after the second
    half kick) books the step at the full-step velocities (see kernels/observe/energy_budget.py),
    each particle's share apart (`booked`, which travels with it between MPI ranks), summed when
    observed. `scene`: what it reads of one, its state, contact and walls (an MPI rank's part is
    one to it, physics/rank_steps.py)."""

    name = "energy_budget"

    def __init__(self, scene, booked: np.ndarray | None = None):
        self.scene = scene
        state = scene.state
        n = state.particles.count
        # each particle's share of the terms so far [J] (kernels/observe/energy_budget.py)
        self.booked = np.zeros((n, TERMS)) if booked is None else booked
        # the totals of a checkpoint written before the shares were kept per particle [J]
        self.carried = np.zeros(TERMS)
        self.totals = np.zeros(TERMS)
        # kinetic + elastic energy when accounting began [J]
        self.reference = np.zeros(1)
        self.scratch = np.zeros((n, 2, 3))
        self.no_spring = np.zeros(3)  # the spring of every contact when none has friction
        self.every_wall = np.zeros(0, dtype=np.uint64)  # every wall to book, for each particle
        self.vel_half = np.zeros((n, 3))
        self.angvel_half = np.zeros((n, 3))
        self.hist = np.zeros_like(state.neighbors.hist)
        walls = state.walls
        self.still = np.zeros((0 if walls is None else walls.axis.shape[0], 3))
        self.wall_hist = np.zeros((n, 0, 3)) if walls is None else np.zeros_like(walls.hist)
        self.wall_vel_half = np.zeros_like(self.still)
        self.no_walls = (
            np.zeros(0, dtype=np.int64),
            np.zeros(0),
            np.zeros(0),
            self.still,
            self.still,
            self.still,
            np.zeros((0, 1, 6)),
        )
        self.pending = False

    def _stored_energy(self) -> float:
        """Kinetic energy of the particles moved by forces plus the elastic energy [J]."""
        state = self.scene.state
        p = state.particles
        elastic, _ = self.scene.contact.elastic_energy(state)
        if self.scene.walls is not None:
            elastic += self.scene.walls.elastic_energy(state)[0]
        free = p.inv_mass > 0.0
        if free.all():
            kinetic = kinetic_energy(p.vel, p.angvel, p.mass, p.inertia)
        else:
            kinetic = kinetic_energy(p.vel[free], p.angvel[free], p.mass[free], p.inertia[free])
        return float(kinetic) + elastic

    def start(self) -> None:
        """Begin accounting at the current state."""
        self.booked[...] = 0.0
        self.carried[:] = 0.0
        self.reference[0] = self._stored_energy()

    def forces(self, state: State, spring_dt: float | None = None) -> None:
        if spring_dt == 0.0:
            return  # the initial forces: no time passes
        keep_half_step(*self.keep_arguments(state))
        self.pending = True

    def finish_step(self, state: State) -> None:
        if not self.pending:
            return
        self.pending = False
        (accumulate_budget_serial if use_serial() else accumulate_budget)(*self.book_arguments(state))

    def keep_arguments(self, state: State) -> tuple:
        """The arguments of keep_half_step, what `forces` keeps before the contacts; valid until
        the next list build (the springs' array may grow there: made again here)."""
        p, nl, w = state.particles, state.neighbors, state.walls
        if self.hist.shape != nl.hist.shape:  # the neighbour list grew
            self.hist = np.zeros_like(nl.hist)
        if w is None:  # nothing of the walls' to keep
            walls = (self.wall_hist, self.wall_hist, self.still, self.still)
        else:
            walls = (w.hist, self.wall_hist, wall_velocity(w, self.still), self.wall_vel_half)
        return (nl.hist, self.hist, *walls, p.vel, self.vel_half, p.angvel, self.angvel_half)

    def book_arguments(self, state: State) -> tuple:
        """The arguments of accumulate_budget, what `finish_step` books after the kick; valid
        until the next list build."""
        p, box, nl, w = state.particles, state.box, state.neighbors, state.walls
        contact = self.scene.contact
        if w is None:
            walls = self.no_walls
        else:
            predicted = getattr(w, "vel_pred", None)
            full = wall_velocity(w, self.still)
            walls = (
                w.axis,
                w.sign,
                w.coord,
                self.wall_vel_half,
                full if predicted is None else predicted,
                full,
                w.table,
            )
        return (
            p.pos, self.vel_half, self.angvel_half, p.vel_pred, p.angvel_pred, p.vel, p.angvel, p.radius,
            p.mass, p.inertia, p.inv_mass, p.inv_inertia, p.material, nl.nbr, nl.nbr_count, nl.start,
            self.hist, contact.table, contact.law_code, contact.rolling, box.body_acc, box.length,
            box.periodic, *walls, self.wall_hist, state.clock.dt, self.scratch, self.booked, self.no_spring,
            self._walls_to_book(p.count),
        )  # fmt: skip

    def _walls_to_book(self, n: int) -> np.ndarray:
        """The walls to book for each particle (physics/walls.py walls_to_book, made with the
        near-wall list of this step's forces), or every wall where there is none yet."""
        walls = self.scene.walls
        mask = None if walls is None else walls.walls_to_book()
        if mask is None or mask.shape[0] != n:
            if self.every_wall.shape[0] != n:
                self.every_wall = np.full(n, np.iinfo(np.uint64).max, dtype=np.uint64)
            return self.every_wall
        return mask

    def observables(self, state: State) -> dict[str, tuple[float, str]]:
        budget_totals(self.booked, self.totals)
        t = self.totals + self.carried
        change = self._stored_energy() - float(self.reference[0])
        dissipated = t[DAMPING] + t[FRICTION] + t[ROLLING]
        values = {
            "work_gravity": t[GRAVITY],
            "work_walls": t[WALLS],
            "dissipated_damping": t[DAMPING],
            "dissipated_friction": t[FRICTION],
            "dissipated_rolling": t[ROLLING],
            "energy_change": change,
            "energy_balance_residual": t[GRAVITY] + t[WALLS] - change - dissipated,
        }
        return {name: (float(v), UNITS[name]) for name, v in values.items()}

    def prognostic_state(self, state: State) -> dict:
        return {"booked": self.booked, "carried": self.carried, "reference": self.reference}

    def restore(self, state: State, arrays: dict) -> None:
        if "booked" in arrays:
            self.booked[...] = arrays["booked"]
            self.carried[:] = arrays["carried"]
        else:  # written before the shares were kept per particle: its totals carried on
            self.booked[...] = 0.0
            self.carried[:] = arrays["totals"]
        self.reference[:] = arrays["reference"]


def wall_velocity(walls, still: np.ndarray) -> np.ndarray:
    """(W,3) velocity of each wall [m/s]: `still` (zeros) while walls carry no velocity."""
    vel = getattr(walls, "vel", None)
    return still if vel is None else vel
