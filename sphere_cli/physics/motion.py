"""Time integration of the particles: velocity Verlet, see kernels/motion.py."""

from __future__ import annotations

from ..kernels.motion import first_unstable, kick, kick_drift, kick_drift_serial, kick_serial
from ..kernels.serial import use_serial
from ..state import Particles, State
from .module import Module


class Motion(Module):
    name = "particles"

    def kick_drift(self, state: State) -> None:
        """The drift also measures how far the particles have moved since the neighbour list
        was built (NeighborSearch.prepare, next in the step, reads it)."""
        kernel = kick_drift_serial if use_serial() else kick_drift
        state.neighbors.moved2 = kernel(*self.drift_arguments(state), False)

    def kick(self, state: State) -> None:
        (kick_serial if use_serial() else kick)(*self.kick_arguments(state))

    @staticmethod
    def drift_arguments(state: State) -> tuple:
        """The arguments of kernels/motion.py kick_drift (also for kernels/steps.py)."""
        p, box, nl = state.particles, state.box, state.neighbors
        return (
            p.pos,
            p.vel,
            p.angvel,
            p.force,
            p.torque,
            p.inv_mass,
            p.inv_inertia,
            box.lower,
            box.length,
            box.periodic,
            state.clock.dt,
            p.vel_pred,
            p.angvel_pred,
            nl.ref_pos,
        )

    @staticmethod
    def kick_arguments(state: State) -> tuple:
        p = state.particles
        return (p.vel, p.angvel, p.force, p.torque, p.inv_mass, p.inv_inertia, state.clock.dt)

    @staticmethod
    def first_unstable(state: State) -> tuple[int, int]:
        p, box = state.particles, state.box
        i, reason = first_unstable(
            p.pos, p.vel, p.angvel, p.radius, box.lower, box.upper, box.periodic, state.clock.dt
        )
        return int(i), int(reason)

    @staticmethod
    def prognostic_state(state: State) -> dict:
        p = state.particles
        return {name: getattr(p, name) for name in Particles.PROGNOSTIC}

    @staticmethod
    def restore(state: State, arrays: dict) -> None:
        for name in Particles.PROGNOSTIC:
            getattr(state.particles, name)[...] = arrays[name]
