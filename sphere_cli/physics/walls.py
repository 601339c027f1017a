"""Plane walls on the box faces (forces phase): kernels/walls.py with the contact's law and the
wall rows of the parameter tables (physics/materials.py)."""

from __future__ import annotations

import numpy as np

from ..kernels.energy import wall_elastic_energy
from ..kernels.walls import wall_forces
from ..state import State, Walls

AXES = {"x": 0, "y": 1, "z": 2}


def allocate_walls(wall_specs, n_particles: int, lower, upper, wall_table: np.ndarray) -> Walls:
    faces = [w.face for w in wall_specs]
    axis = np.array([AXES[f[0]] for f in faces], dtype=np.int64)
    sign = np.array([1.0 if f[1] == "-" else -1.0 for f in faces])
    coord = np.array([lower[a] if s > 0 else upper[a] for a, s in zip(axis, sign, strict=True)])
    return Walls(
        faces=faces,
        axis=axis,
        sign=sign,
        coord=coord,
        table=np.ascontiguousarray(wall_table),
        hist=np.zeros((n_particles, len(faces), 3)),
    )


class PlaneWallForces:
    phase = "forces"

    def __init__(self, contact):
        self.contact = contact  # shares the law (linear or Hertz) and the rolling switch

    def forces(self, state: State, spring_dt: float | None = None) -> None:
        p, w, c = state.particles, state.walls, self.contact
        dt = state.clock.dt
        wall_forces(
            p.pos,
            p.vel,
            p.angvel,
            p.vel_pred,
            p.angvel_pred,
            p.radius,
            p.mass,
            p.inertia,
            p.material,
            w.axis,
            w.sign,
            w.coord,
            w.table,
            w.hist,
            c.hertz,
            c.rolling,
            dt if spring_dt is None else spring_dt,
            dt,
            p.force,
            p.torque,
        )

    def elastic_energy(self, state: State) -> tuple[float, int]:
        p, w, c = state.particles, state.walls, self.contact
        energy, touching = wall_elastic_energy(
            p.pos, p.radius, p.material, w.axis, w.sign, w.coord, w.table, w.hist, c.hertz
        )
        return float(energy), int(touching)

    @staticmethod
    def prognostic_state(state: State) -> dict:
        return {name: getattr(state.walls, name) for name in Walls.PROGNOSTIC}

    @staticmethod
    def restore(state: State, arrays: dict) -> None:
        for name in Walls.PROGNOSTIC:
            getattr(state.walls, name)[...] = arrays[name]
