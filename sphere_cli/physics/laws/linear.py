"""The linear spring-dashpot (Cundall & Strack 1979): F_n = k_n delta - c_n v_n, tangential
spring k_t; damping ratio zeta calibrated to the restitution (physics/restitution.py)."""

from __future__ import annotations

import math

from ...kernels.laws import LINEAR
from ..restitution import linear_damping_ratio
from .base import ContactLaw


def _series(a: float, b: float) -> float:
    return 2.0 * a * b / (a + b)


class Linear(ContactLaw):
    """Stiffnesses of two materials in series, k = 2 k_a k_b/(k_a + k_b) for k_n and k_t (like
    pairs keep the material's k); a wall without a material uses the particle material's own k.
    k_t defaults to 2/7 k_n."""

    name = "linear"
    label = "linear"
    code = LINEAR

    def resolve(self, pick, spec) -> dict:
        kn = pick("normal_stiffness")
        kt = pick("tangential_stiffness")
        if spec is not None and spec.normal_stiffness is not None and spec.tangential_stiffness is None:
            kt = None  # a material's own k_n implies its own default k_t
        return dict(normal_stiffness=kn, tangential_stiffness=2.0 / 7.0 * kn if kt is None else kt)

    def mix(self, a, b) -> dict:
        if b is None:
            return dict(normal_stiffness=a.normal_stiffness, tangential_stiffness=a.tangential_stiffness)
        return dict(
            normal_stiffness=_series(a.normal_stiffness, b.normal_stiffness),
            tangential_stiffness=_series(a.tangential_stiffness, b.tangential_stiffness),
        )

    def elastic_row(self, law) -> tuple[float, float, float, float]:
        zeta = linear_damping_ratio(law.restitution)
        return (
            law.normal_stiffness,
            law.tangential_stiffness,
            2.0 * zeta * math.sqrt(law.normal_stiffness),
            2.0 * zeta * math.sqrt(law.tangential_stiffness),
        )

    def limit_note(self, overlap: float) -> str:
        return (
            ": 2(sqrt(1+4 zeta^2)-2 zeta)/omega for the normal (omega^2 = k_n/m*) and the "
            "rotation-coupled tangential mode (omega^2 = 3.5 k_t/m*, damping ratio sqrt(3.5) zeta)"
        )
