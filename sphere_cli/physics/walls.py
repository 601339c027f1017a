"""Plane walls on the box faces (forces phase): kernels/walls.py with the contact's law."""

from __future__ import annotations

import numpy as np

from ..kernels.energy import linear_wall_elastic_energy
from ..kernels.walls import linear_wall_forces
from ..state import State, Walls

AXES = {"x": 0, "y": 1, "z": 2}


def allocate_walls(wall_specs, n_particles: int, lower, upper, default_mu: float) -> Walls:
    faces = [w.face for w in wall_specs]
    axis = np.array([AXES[f[0]] for f in faces], dtype=np.int64)
    sign = np.array([1.0 if f[1] == "-" else -1.0 for f in faces])
    coord = np.array([lower[a] if s > 0 else upper[a] for a, s in zip(axis, sign, strict=True)])
    mu = np.array([default_mu if w.friction is None else w.friction for w in wall_specs])
    return Walls(
        faces=faces, axis=axis, sign=sign, coord=coord, mu=mu, hist=np.zeros((n_particles, len(faces), 3))
    )


class PlaneWallForces:
    phase = "forces"

    def __init__(self, contact):
        self.contact = contact  # shares stiffness and calibrated damping

    def forces(self, state: State, spring_dt: float | None = None) -> None:
        p, w, c = state.particles, state.walls, self.contact
        dt = state.clock.dt if spring_dt is None else spring_dt
        linear_wall_forces(
            p.pos,
            p.vel,
            p.angvel,
            p.vel_pred,
            p.angvel_pred,
            p.radius,
            p.mass,
            w.axis,
            w.sign,
            w.coord,
            w.mu,
            w.hist,
            c.kn,
            c.kt,
            c.zeta,
            dt,
            p.force,
            p.torque,
        )

    def elastic_energy(self, state: State) -> tuple[float, int]:
        p, w, c = state.particles, state.walls, self.contact
        energy, touching = linear_wall_elastic_energy(
            p.pos, p.radius, w.axis, w.sign, w.coord, w.hist, c.kn, c.kt
        )
        return float(energy), int(touching)

    @staticmethod
    def prognostic_state(state: State) -> dict:
        return {name: getattr(state.walls, name) for name in Walls.PROGNOSTIC}

    @staticmethod
    def restore(state: State, arrays: dict) -> None:
        for name in Walls.PROGNOSTIC:
            getattr(state.walls, name)[...] = arrays[name]
