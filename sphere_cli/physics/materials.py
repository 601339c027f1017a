"""Materials and the per-pair contact parameters (no kernels: the tables feed kernels/contact.py
and kernels/walls.py).

A scene has M particle materials (M = 1 for the single-material form: particles.density and
the properties of [contact]); every particle carries a material id. Each pair of materials,
and each wall against each material, gets one row of contact parameters, built by these rules
unless [[contact.pairs]] (or walls[].friction) gives a value explicitly:

- Hertz-Mindlin: 1/E* = (1 - nu_a^2)/E_a + (1 - nu_b^2)/E_b and
  1/G* = (2 - nu_a)/G_a + (2 - nu_b)/G_b with G = E/(2 (1 + nu)) (Hertz 1882; Mindlin 1949;
  verification group A2). A rigid wall (no material) adds nothing: 1/E* = (1 - nu_a^2)/E_a.
- Linear: k = 2 k_a k_b/(k_a + k_b) for k_n and k_t, two half-contacts in series (like pairs
  keep the material's k). A wall without a material uses the particle material's own k.
- Restitution, friction and rolling friction: the arithmetic mean (e_a + e_b)/2; against a
  wall without a material, the particle material's own values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config.consistency import particle_materials
from ..config.schema import Case
from ..kernels.contact import COLUMNS, D_N, D_T, K_N, K_T, MU, MU_R
from .restitution import hertz_damping_coefficient, linear_damping_ratio

SINGLE = ""  # name of the one material of the single-material form


@dataclass(frozen=True)
class Material:
    """One material with every property resolved ([contact] supplies those it leaves out)."""

    name: str
    density: float | None
    restitution: float
    friction: float
    rolling_friction: float
    youngs_modulus: float | None = None  # Hertz-Mindlin [Pa]
    poisson_ratio: float | None = None  # Hertz-Mindlin [-]
    normal_stiffness: float | None = None  # linear [N/m]
    tangential_stiffness: float | None = None  # linear [N/m]

    @property
    def shear_modulus(self) -> float:
        return self.youngs_modulus / (2.0 * (1.0 + self.poisson_ratio))


@dataclass(frozen=True)
class PairLaw:
    """The contact of one pair (or of a wall and a material), before the calibration of damping."""

    restitution: float
    friction: float
    rolling_friction: float
    normal_stiffness: float = math.nan  # linear k_n [N/m]
    tangential_stiffness: float = math.nan  # linear k_t [N/m]
    e_star: float = math.nan  # Hertz effective Young's modulus [Pa]
    g_star: float = math.nan  # Mindlin effective shear modulus [Pa]


@dataclass
class ContactTables:
    hertz: bool
    names: list[str]  # particle materials, by id
    materials: list[Material]  # by id
    fractions: list[float]  # number fractions, by id
    table: np.ndarray  # (M,M,6) pair rows (kernels/contact.py)
    wall_table: np.ndarray  # (W,M,6) wall rows
    pair_laws: dict  # (a, b) -> PairLaw, a <= b
    wall_laws: dict  # (w, a) -> PairLaw

    @property
    def rolling(self) -> bool:
        return bool(np.any(self.table[..., MU_R] > 0.0) or np.any(self.wall_table[..., MU_R] > 0.0))


def _resolve(case: Case, spec) -> Material:
    """A [[materials]] entry (or None for the single-material form) with [contact]'s defaults."""
    contact = case.contact
    hertz = contact.model == "hertz-mindlin"

    def pick(key):
        own = None if spec is None else getattr(spec, key)
        return getattr(contact, key) if own is None else own

    common = dict(
        name=SINGLE if spec is None else spec.name,
        density=case.particles.density if spec is None else spec.density,
        restitution=pick("restitution"),
        friction=pick("friction"),
        rolling_friction=pick("rolling_friction"),
    )
    if hertz:
        return Material(**common, youngs_modulus=pick("youngs_modulus"), poisson_ratio=pick("poisson_ratio"))
    kn = pick("normal_stiffness")
    kt = pick("tangential_stiffness")
    if spec is not None and spec.normal_stiffness is not None and spec.tangential_stiffness is None:
        kt = None  # a material's own k_n implies its own default k_t
    return Material(**common, normal_stiffness=kn, tangential_stiffness=2.0 / 7.0 * kn if kt is None else kt)


def _series(a: float, b: float) -> float:
    return 2.0 * a * b / (a + b)


def mix(a: Material, b: Material | None, hertz: bool, override=None) -> PairLaw:
    """The contact law of materials a and b (b None: a rigid wall), by the rules of this module;
    `override` (a [[contact.pairs]] entry) replaces what it sets."""
    if b is None:
        surface = dict(restitution=a.restitution, friction=a.friction, rolling_friction=a.rolling_friction)
    else:
        surface = {
            key: 0.5 * (getattr(a, key) + getattr(b, key))
            for key in ("restitution", "friction", "rolling_friction")
        }
    if hertz:
        inv_e = (1.0 - a.poisson_ratio**2) / a.youngs_modulus
        inv_g = (2.0 - a.poisson_ratio) / a.shear_modulus
        if b is not None:
            inv_e += (1.0 - b.poisson_ratio**2) / b.youngs_modulus
            inv_g += (2.0 - b.poisson_ratio) / b.shear_modulus
        elastic = dict(e_star=1.0 / inv_e, g_star=1.0 / inv_g)
    elif b is None:
        elastic = dict(normal_stiffness=a.normal_stiffness, tangential_stiffness=a.tangential_stiffness)
    else:
        elastic = dict(
            normal_stiffness=_series(a.normal_stiffness, b.normal_stiffness),
            tangential_stiffness=_series(a.tangential_stiffness, b.tangential_stiffness),
        )
    law = {**surface, **elastic}
    if override is not None:
        for key in (
            "restitution",
            "friction",
            "rolling_friction",
            "normal_stiffness",
            "tangential_stiffness",
        ):
            value = getattr(override, key, None)
            if value is not None:
                law[key] = value
        if getattr(override, "normal_stiffness", None) is not None and override.tangential_stiffness is None:
            law["tangential_stiffness"] = 2.0 / 7.0 * override.normal_stiffness
    return PairLaw(**law)


def table_row(law: PairLaw, hertz: bool) -> np.ndarray:
    """The kernel's parameter row (K_N, K_T, D_N, D_T, MU, MU_R) of one pair, damping calibrated
    to its restitution (physics/restitution.py)."""
    row = np.zeros(COLUMNS)
    if hertz:
        c_h = hertz_damping_coefficient(law.restitution)
        row[K_N] = 4.0 / 3.0 * law.e_star
        row[K_T] = 8.0 * law.g_star
        row[D_N] = c_h * math.sqrt(4.0 / 3.0 * law.e_star)
        row[D_T] = c_h * math.sqrt(16.0 / 3.0 * law.g_star)
    else:
        zeta = linear_damping_ratio(law.restitution)
        row[K_N] = law.normal_stiffness
        row[K_T] = law.tangential_stiffness
        row[D_N] = 2.0 * zeta * math.sqrt(law.normal_stiffness)
        row[D_T] = 2.0 * zeta * math.sqrt(law.tangential_stiffness)
    row[MU] = law.friction
    row[MU_R] = law.rolling_friction
    return row


def contact_tables(case: Case) -> ContactTables:
    hertz = case.contact.model == "hertz-mindlin"
    by_name = {m.name: m for m in case.materials}
    fractions = particle_materials(case)
    if fractions:
        materials = [_resolve(case, by_name[name]) for name in fractions]
    else:
        materials = [_resolve(case, None)]
        fractions = {SINGLE: 1.0}
    names = list(fractions)
    overrides = {frozenset(p.materials): p for p in case.contact.pairs}
    m = len(materials)
    table = np.zeros((m, m, COLUMNS))
    pair_laws = {}
    for a in range(m):
        for b in range(a, m):
            law = mix(materials[a], materials[b], hertz, overrides.get(frozenset((names[a], names[b]))))
            pair_laws[(a, b)] = law
            table[a, b] = table[b, a] = table_row(law, hertz)
    wall_table = np.zeros((len(case.walls), m, COLUMNS))
    wall_laws = {}
    for w, wall in enumerate(case.walls):
        wall_material = None if wall.material is None else _resolve(case, by_name[wall.material])
        for a in range(m):
            override = None
            if wall.material is not None:
                override = overrides.get(frozenset((names[a], wall.material)))
            law = mix(materials[a], wall_material, hertz, override)
            if wall.friction is not None:
                law = PairLaw(**{**law.__dict__, "friction": wall.friction})
            wall_laws[(w, a)] = law
            wall_table[w, a] = table_row(law, hertz)
    return ContactTables(
        hertz=hertz,
        names=names,
        materials=materials,
        fractions=list(fractions.values()),
        table=table,
        wall_table=wall_table,
        pair_laws=pair_laws,
        wall_laws=wall_laws,
    )


def assign_materials(fractions: list[float], n: int, rng) -> np.ndarray:
    """Material id of each of n particles (int32): exact counts round(f n) by largest remainders,
    in an order shuffled by rng."""
    if len(fractions) == 1:
        return np.zeros(n, dtype=np.int32)
    share = np.asarray(fractions) * n
    counts = np.floor(share).astype(np.int64)
    rest = n - int(counts.sum())
    order = np.argsort(-(share - counts), kind="stable")
    counts[order[:rest]] += 1
    ids = np.repeat(np.arange(len(fractions), dtype=np.int32), counts)
    return rng.permutation(ids).astype(np.int32)
