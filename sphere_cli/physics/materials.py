"""Materials and the per-pair contact parameters (no kernels: the tables, whose columns
kernels/laws.py defines, feed kernels/contact.py and kernels/walls.py).

A scene has M particle materials (M = 1 for the single-material form: particles.density and
the properties of [contact]); every particle carries a material id. Each pair of materials,
and each wall against each material, gets one row of contact parameters, built by these rules
unless [[contact.pairs]] (or walls[].friction) gives a value explicitly:

- The elastic properties: by the contact law's own rule (physics/laws/).
- Restitution, friction and rolling friction: the arithmetic mean (e_a + e_b)/2; against a
  wall without a material, the particle material's own values.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..config.consistency import particle_materials
from ..config.schema import Case
from ..kernels.laws import COLUMNS, D_N, D_T, K_N, K_T, MU, MU_R
from .laws import LAWS, ContactLaw

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
    law: ContactLaw
    names: list[str]  # particle materials, by id
    materials: list[Material]  # by id
    fractions: list[float]  # number fractions, by id
    table: np.ndarray  # (M,M,6) pair rows (columns of kernels/laws.py)
    wall_table: np.ndarray  # (W,M,6) wall rows
    pair_laws: dict  # (a, b) -> PairLaw, a <= b
    wall_laws: dict  # (w, a) -> PairLaw
    # some contact has friction in some stage: only then do contacts carry tangential springs
    # (with mu = 0 the spring is capped to zero at every step, so it is left out)
    frictional: bool = True

    def label(self, a: int) -> str:
        """Material a in a message."""
        return "the particles" if self.names[a] == "" else f"material {self.names[a]!r}"

    @property
    def rolling(self) -> bool:
        return bool(np.any(self.table[..., MU_R] > 0.0) or np.any(self.wall_table[..., MU_R] > 0.0))


def _resolve(case: Case, law: ContactLaw, spec) -> Material:
    """A [[materials]] entry (or None for the single-material form) with [contact]'s defaults."""
    contact = case.contact

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
    return Material(**common, **law.resolve(pick, spec))


def mix(a: Material, b: Material | None, contact_law: ContactLaw, override=None) -> PairLaw:
    """The contact law of materials a and b (b None: a rigid wall), by the rules of this module;
    `override` (a [[contact.pairs]] entry) replaces what it sets."""
    if b is None:
        surface = dict(restitution=a.restitution, friction=a.friction, rolling_friction=a.rolling_friction)
    else:
        surface = {
            key: 0.5 * (getattr(a, key) + getattr(b, key))
            for key in ("restitution", "friction", "rolling_friction")
        }
    law = {**surface, **contact_law.mix(a, b)}
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


def table_row(law: PairLaw, contact_law: ContactLaw) -> np.ndarray:
    """The kernel's parameter row (K_N, K_T, D_N, D_T, MU, MU_R) of one pair, damping calibrated
    to its restitution (physics/restitution.py)."""
    row = np.zeros(COLUMNS)
    row[K_N], row[K_T], row[D_N], row[D_T] = contact_law.elastic_row(law)
    row[MU] = law.friction
    row[MU_R] = law.rolling_friction
    return row


def contact_tables(case: Case) -> ContactTables:
    contact_law = LAWS[case.contact.model]
    by_name = {m.name: m for m in case.materials}
    fractions = particle_materials(case)
    if fractions:
        materials = [_resolve(case, contact_law, by_name[name]) for name in fractions]
    else:
        materials = [_resolve(case, contact_law, None)]
        fractions = {SINGLE: 1.0}
    names = list(fractions)
    overrides = {frozenset(p.materials): p for p in case.contact.pairs}
    m = len(materials)
    table = np.zeros((m, m, COLUMNS))
    pair_laws = {}
    for a in range(m):
        for b in range(a, m):
            law = mix(materials[a], materials[b], contact_law, overrides.get(frozenset((names[a], names[b]))))
            pair_laws[(a, b)] = law
            table[a, b] = table[b, a] = table_row(law, contact_law)
    wall_table = np.zeros((len(case.walls), m, COLUMNS))
    wall_laws = {}
    for w, wall in enumerate(case.walls):
        wall_material = None if wall.material is None else _resolve(case, contact_law, by_name[wall.material])
        for a in range(m):
            override = None
            if wall.material is not None:
                override = overrides.get(frozenset((names[a], wall.material)))
            law = mix(materials[a], wall_material, contact_law, override)
            if wall.friction is not None:
                law = PairLaw(**{**law.__dict__, "friction": wall.friction})
            wall_laws[(w, a)] = law
            wall_table[w, a] = table_row(law, contact_law)
    return ContactTables(
        law=contact_law,
        names=names,
        materials=materials,
        fractions=list(fractions.values()),
        table=table,
        wall_table=wall_table,
        pair_laws=pair_laws,
        wall_laws=wall_laws,
        frictional=bool(
            np.any(table[..., MU] > 0.0)
            or np.any(wall_table[..., MU] > 0.0)
            or any((stage.friction or 0.0) > 0.0 for stage in case.stages)
        ),
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
