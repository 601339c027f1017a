"""Particle-particle contacts (forces phase): the linear spring-dashpot law of
kernels/contact.py, its calibrated damping, and the time-step limit it imposes."""

from __future__ import annotations

import math

import numpy as np

from ..config.schema import LinearContact
from ..kernels.contact import linear_pair_forces
from ..kernels.energy import linear_pair_elastic_energy
from ..state import State
from .restitution import linear_damping_ratio


class LinearContactForces:
    phase = "forces"

    def __init__(self, params: LinearContact):
        self.kn = params.normal_stiffness
        self.kt = params.kt
        self.mu = params.friction
        self.zeta = linear_damping_ratio(params.restitution)

    def forces(self, state: State, spring_dt: float | None = None) -> None:
        """Pair forces at the current positions; the tangential springs grow by the slip over
        `spring_dt` (default: one step; 0 for the forces of the initial state)."""
        p, box, nl = state.particles, state.box, state.neighbors
        dt = state.clock.dt if spring_dt is None else spring_dt
        linear_pair_forces(
            p.pos,
            p.vel,
            p.angvel,
            p.vel_pred,
            p.angvel_pred,
            p.radius,
            p.mass,
            nl.nbr,
            nl.nbr_count,
            nl.hist,
            self.kn,
            self.kt,
            self.zeta,
            self.mu,
            box.body_acc,
            box.length,
            box.periodic,
            dt,
            p.force,
            p.torque,
        )

    def critical_dt(self, m_eff: float) -> float:
        """Stability limit of velocity Verlet for this contact at reduced mass m_eff [s].

        The stiffest mode is normal (omega^2 = k_n/m*) or tangential with the rolling coupling
        of two spheres (omega^2 = 3.5 k_t/m*); the dashpot lowers the central-difference limit
        to 2 (sqrt(1 + zeta^2) - zeta)/omega. No possible contact (m_eff infinite): no limit.
        """
        if not math.isfinite(m_eff):
            return math.inf
        omega = math.sqrt(max(self.kn, 3.5 * self.kt) / m_eff)
        return 2.0 * (math.sqrt(1.0 + self.zeta**2) - self.zeta) / omega

    def elastic_energy(self, state: State) -> tuple[float, int]:
        p, box, nl = state.particles, state.box, state.neighbors
        energy, pairs = linear_pair_elastic_energy(
            p.pos, p.radius, nl.nbr, nl.nbr_count, nl.hist, self.kn, self.kt, box.length, box.periodic
        )
        return float(energy), int(pairs)


def smallest_pair_mass(mass: np.ndarray) -> float:
    """Smallest reduced mass of any possible pair: the two lightest particles [kg]."""
    if mass.size < 2:
        return float("inf")
    two = np.partition(mass, 1)[:2]
    return float(two[0] * two[1] / (two[0] + two[1]))
