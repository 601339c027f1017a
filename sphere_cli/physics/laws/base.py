"""What a contact law is to the rest of the program: its parameters per material and per pair,
its row of the contact table, and its stiffness and damping for the time-step limits."""

from __future__ import annotations

import math
from abc import ABC, abstractmethod

import numpy as np

from ...kernels.laws import D_N, D_T, K_N, K_T


class ContactLaw(ABC):
    """One contact law, chosen by `[contact] model` (physics/laws/__init__.py LAWS). A new law
    subclasses this, adds its code and branch to kernels/laws.py normal_law and its elastic
    energy to kernels/observe/energy.py, and its parameters to the schema."""

    name = ""  # the [contact] model tag
    label = ""  # in messages
    code = -1  # the kernels' law code (kernels/laws.py)

    @abstractmethod
    def resolve(self, pick, spec) -> dict:
        """The elastic properties of a material ([[materials]] entry `spec`, None for the
        single-material form); pick(key) gives the material's value or [contact]'s."""

    @abstractmethod
    def mix(self, a, b) -> dict:
        """The elastic part of the law of a pair of materials a and b (b None: a rigid wall)."""

    @abstractmethod
    def elastic_row(self, law) -> tuple[float, float, float, float]:
        """The columns K_N, K_T, D_N, D_T of a pair law (physics/materials.py PairLaw), damping
        calibrated so that the clamped contact rebounds at its restitution."""

    def scale(self, r_eff: float, delta: float) -> float:
        """s of kernels/laws.py: the stiffness columns times s are the tangent stiffnesses at
        effective radius r_eff [m] and overlap delta [m]."""
        return 1.0

    def normal_stiffness(self, row: np.ndarray, r_eff: float, delta: float) -> float:
        """The tangent normal stiffness dF_n/d delta [N/m] of a table row."""
        return row[K_N]

    def static_overlap(self, row: np.ndarray, r_eff: float, force: float) -> float:
        """The overlap [m] at which a table row's elastic normal force is `force` [N]."""
        return force / row[K_N]

    def impact_overlap(self, row: np.ndarray, r_eff: float, m_eff: float, speed: float) -> float:
        """The deepest overlap [m] of a head-on impact at `speed` [m/s] of effective mass m_eff
        [kg], the dashpot left out: 1/2 m* v^2 = 1/2 K_N delta^2."""
        return speed * math.sqrt(m_eff / row[K_N])

    def damping_ratio(self, row: np.ndarray) -> float:
        """The damping ratio of the normal dashpot of a table row (independent of the overlap)."""
        return row[D_N] / (2.0 * math.sqrt(row[K_N]))

    def impact_limits(self, tables, lightest: dict, radius: np.ndarray) -> list[tuple[float, str]]:
        """Limits on dt of an impact that are not those of a contact's modes (the Rayleigh time
        for Hertz): (value [s], what) for each material."""
        return []

    def limit_note(self, overlap: float) -> str:
        """What the one-contact limit of this law is, appended to its message."""
        return self.tangent_note(overlap)

    def tangent_note(self, overlap: float) -> str:
        """Where the stiffnesses of a limit are taken, when they depend on the overlap."""
        return ""

    def coefficients(self, row: np.ndarray, r_eff: float, delta: float) -> tuple[float, float]:
        """(kappa [N/m], d [kg^1/2/s]) of one table row: the largest stiffness a contact offers a
        sphere that it holds, max(k_n, 3.5 k_t) (the tangential spring also turns the sphere,
        1 + m r^2/I = 3.5), and likewise its damping max(c_n, 3.5 c_t) = d sqrt(m*)."""
        s = self.scale(r_eff, delta)
        kappa = max(self.normal_stiffness(row, r_eff, delta), 3.5 * row[K_T] * s)
        return kappa, max(row[D_N], 3.5 * row[D_T]) * math.sqrt(s)
