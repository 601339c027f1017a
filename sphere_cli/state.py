"""Plain containers of arrays: the whole state of a run, and nothing that is not needed.

A container exists only when the case needs it (no walls: `walls` is None; a dry scene:
`fluid` is None). Arrays are allocated once by the builder; the time loop only writes into
them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class Clock:
    dt: float
    step: int = 0

    @property
    def time(self) -> float:
        # computed, not accumulated: no drift, and bitwise equal after a restart
        return self.step * self.dt

    def steps_in(self, span: float) -> int:
        """The one rule for every span of simulated time a case gives (the run's duration, a
        stage's, the output schedules, a fluid's coupling interval): the nearest whole number of
        steps, at least one."""
        return max(1, round(span / self.dt))


@dataclass
class Box:
    lower: np.ndarray  # (3,) [m]
    upper: np.ndarray  # (3,) [m]
    periodic: np.ndarray  # (3,) uint8
    body_acc: np.ndarray  # (3,) [m/s^2] gravity

    @property
    def length(self) -> np.ndarray:
        return self.upper - self.lower


@dataclass
class Particles:
    pos: np.ndarray  # (N,3) [m]
    vel: np.ndarray  # (N,3) [m/s]
    angvel: np.ndarray  # (N,3) [rad/s]
    force: np.ndarray  # (N,3) [N], at the current step (the next half kick needs it)
    torque: np.ndarray  # (N,3) [N m]
    radius: np.ndarray  # (N,) [m]
    mass: np.ndarray  # (N,) [kg]
    inertia: np.ndarray  # (N,) [kg m^2]
    inv_mass: np.ndarray  # (N,) [1/kg]
    inv_inertia: np.ndarray  # (N,) [1/(kg m^2)]
    material: np.ndarray  # (N,) int32 material id (all 0 with one material)
    # scratch, rewritten by every kick_drift (not prognostic): v_n + dt a_n, the dashpots'
    # second-order estimate of v_{n+1}
    vel_pred: np.ndarray | None = None  # (N,3) [m/s]
    angvel_pred: np.ndarray | None = None  # (N,3) [rad/s]

    @property
    def count(self) -> int:
        return self.pos.shape[0]

    PROGNOSTIC = (
        "pos",
        "vel",
        "angvel",
        "force",
        "torque",
        "radius",
        "mass",
        "inertia",
        "inv_mass",
        "inv_inertia",
        "material",
    )


@dataclass
class NeighborList:
    """Half Verlet list with skin and the tangential spring of every listed pair (see
    kernels/neighbors.py): row i lists the j > i near i, so each pair appears once."""

    skin: float  # [m]
    nbr: np.ndarray  # (N,C) int32, row i: the j > i within reach, ascending
    nbr_count: np.ndarray  # (N,) int32
    start: np.ndarray  # (N+1,) int64 pairs listed before row i (derived from nbr_count)
    hist: np.ndarray  # (>= P,3) [m] spring of pair (i, nbr[i, k]) seen from i, at start[i] + k
    ref_pos: np.ndarray  # (N,3) positions at the last build [m]
    # reverse list, derived from the above at every build and restore (not state): rev[i] holds
    # the packed indices start[j] + k of the pairs (j, i) with j < i, ascending in j
    rev: np.ndarray | None = None  # (N,R) int32
    rev_count: np.ndarray | None = None  # (N,) int32
    builds: int = 0
    # largest squared displacement since the build [m^2], measured by the drift of each step
    # (physics/motion.py); inf until then, so a check before any drift rebuilds
    moved2: float = math.inf

    # checkpoints hold hist in rows like nbr, (N,C,3) (physics/neighbors.py)
    PROGNOSTIC = ("nbr", "nbr_count", "hist", "ref_pos")


@dataclass
class Walls:
    """Plane walls and their motion (physics/walls.py). `vel` is that of the current step;
    `force` too for every wall that moves (energy budgets integrate force . velocity from them);
    a fixed wall's force (zero work) is refreshed only when observed."""

    faces: list[str]
    axis: np.ndarray  # (W,) int64
    sign: np.ndarray  # (W,) float64, +1 lower face, -1 upper face
    coord: np.ndarray  # (W,) [m] position along the axis
    table: np.ndarray  # (W,M,6) contact parameters of each wall against each material
    hist: np.ndarray  # (N,W,3) [m]
    vel: np.ndarray  # (W,3) [m/s] velocity at the current step (a half step after kick_drift)
    acc: np.ndarray  # (W,3) [m/s^2] acceleration of the driven directions
    shift: np.ndarray  # (W,3) [m] displacement since the start of the run
    force: np.ndarray  # (W,3) [N] force of the particles (and of a pore fluid it bounds) on each wall
    area: np.ndarray  # (W,) [m^2]
    mode: np.ndarray  # (W,2) int64 normal and shear mode (kernels/walls.py)
    control: np.ndarray  # (W,NC) parameters of the modes (kernels/walls.py)
    attached: np.ndarray  # (K,) int64 particles glued to a wall (rough walls)
    attached_wall: np.ndarray  # (K,) int64 their wall
    # scratch: predicted velocity (W,3); each particle's force from the walls marked in
    # `record` (W,) uint8 (the moving ones), (N,W,3) if some wall ever moves, else (0,W,3)
    vel_pred: np.ndarray = None
    pforce: np.ndarray = None
    record: np.ndarray = None
    # the exact sums of the forces on the walls (kernels/walls.py wall_totals), (W, 3, WORDS)
    # int64, made by physics/walls.py wall_sums
    sums: np.ndarray = None
    # (W,3) [N] force of the pore fluid on a wall that bounds a Darcy fluid (an impermeable top
    # wall the grid follows; physics/fluid/darcy.py sets it every fluid step), else zero
    fluid_force: np.ndarray = None
    # (n,) int64 ascending: the particles listed near the walls, the only rows of pforce that
    # may not be zero (physics/walls.py PlaneWallForces lists them, zeroing every row; none
    # before the first list)
    listed: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    PROGNOSTIC = ("coord", "hist", "vel", "acc", "shift", "force", "attached", "attached_wall")


@dataclass
class State:
    clock: Clock
    box: Box
    particles: Particles  # empty arrays in a scene without particles (a fluid-only one)
    neighbors: NeighborList | None  # None without particles
    walls: Walls | None = None
    fluid: object | None = None
