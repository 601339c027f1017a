"""Hertz-Mindlin with the Tsuji dashpot: F_n = (4/3) E* sqrt(R*) delta^{3/2} - damping, Mindlin's
no-slip tangential stiffness 8 G* sqrt(R* delta); the damping coefficient c_h calibrated to the
restitution at every impact speed (physics/restitution.py)."""

from __future__ import annotations

import math

import numpy as np

from ...kernels.laws import D_N, HERTZ_MINDLIN, K_N
from ..restitution import hertz_damping_coefficient
from .base import ContactLaw


def rayleigh_time(radius: float, density: float, shear_modulus: float, poisson_ratio: float) -> float:
    """pi r sqrt(rho/G)/(0.1631 nu + 0.8766) [s] (Li, Xu & Thornton 2005)."""
    return math.pi * radius * math.sqrt(density / shear_modulus) / (0.1631 * poisson_ratio + 0.8766)


class HertzMindlin(ContactLaw):
    """1/E* = (1 - nu_a^2)/E_a + (1 - nu_b^2)/E_b and 1/G* = (2 - nu_a)/G_a + (2 - nu_b)/G_b with
    G = E/(2 (1 + nu)) (Hertz 1882; Mindlin 1949; verification group A2). A rigid wall (no
    material) adds nothing: 1/E* = (1 - nu_a^2)/E_a."""

    name = "hertz-mindlin"
    label = "Hertz-Mindlin"
    code = HERTZ_MINDLIN

    def resolve(self, pick, spec) -> dict:
        return dict(youngs_modulus=pick("youngs_modulus"), poisson_ratio=pick("poisson_ratio"))

    def mix(self, a, b) -> dict:
        inv_e = (1.0 - a.poisson_ratio**2) / a.youngs_modulus
        inv_g = (2.0 - a.poisson_ratio) / a.shear_modulus
        if b is not None:
            inv_e += (1.0 - b.poisson_ratio**2) / b.youngs_modulus
            inv_g += (2.0 - b.poisson_ratio) / b.shear_modulus
        return dict(e_star=1.0 / inv_e, g_star=1.0 / inv_g)

    def elastic_row(self, law) -> tuple[float, float, float, float]:
        c_h = hertz_damping_coefficient(law.restitution)
        return (
            4.0 / 3.0 * law.e_star,
            8.0 * law.g_star,
            c_h * math.sqrt(4.0 / 3.0 * law.e_star),
            c_h * math.sqrt(16.0 / 3.0 * law.g_star),
        )

    def scale(self, r_eff: float, delta: float) -> float:
        return math.sqrt(r_eff * delta)

    def normal_stiffness(self, row: np.ndarray, r_eff: float, delta: float) -> float:
        # dF/d delta of K_N sqrt(R*) delta^{3/2}
        return 1.5 * row[K_N] * math.sqrt(r_eff * delta)

    def static_overlap(self, row: np.ndarray, r_eff: float, force: float) -> float:
        # F = K_N sqrt(R*) delta^{3/2} solved for delta
        return (force / (row[K_N] * math.sqrt(r_eff))) ** (2.0 / 3.0)

    def impact_overlap(self, row: np.ndarray, r_eff: float, m_eff: float, speed: float) -> float:
        # 1/2 m* v^2 = (2/5) K_N sqrt(R*) delta^{5/2}
        return (1.25 * m_eff * speed * speed / (row[K_N] * math.sqrt(r_eff))) ** 0.4

    def damping_ratio(self, row: np.ndarray) -> float:
        return row[D_N] / (2.0 * math.sqrt(1.5 * row[K_N]))  # c_h/sqrt6

    def impact_limits(self, tables, lightest: dict, radius: np.ndarray) -> list[tuple[float, str]]:
        limits = []
        for a, first in lightest.items():
            mat = tables.materials[a]
            r = float(radius[first[0]])
            limits.append(
                (
                    rayleigh_time(r, mat.density, mat.shear_modulus, mat.poisson_ratio),
                    f"Rayleigh time pi r sqrt(rho/G)/(0.1631 nu + 0.8766) of the smallest particle of "
                    f"{tables.label(a)}, r = {r:.4g} m",
                )
            )
        return limits

    def limit_note(self, overlap: float) -> str:
        return f" (tangent stiffness at {overlap:g} of the radius, the largest initial overlap)"

    def tangent_note(self, overlap: float) -> str:
        return f" (tangent stiffness at {overlap:g} of the radius)"
