"""Particle-particle contacts (the forces hook): the contact law of kernels/laws.py
(physics/laws/), swept over the pairs by kernels/contact.py, with per-pair parameters
(physics/materials.py), and the time-step limits the contacts impose.

Time-step limits (verification group E; user guide section 2). The dashpots act at the
predicted velocity v_n + dt a_n (kernels/motion.py): on a damped linear mode (omega, zeta) that
velocity Verlet is stable while omega dt <= 2 (sqrt(1 + 4 zeta^2) - 2 zeta), the central-difference
limit with zeta doubled (its amplification matrix of (x, v, a) has det(M + I) = 4 - h^2 - 8 zeta h,
h = omega dt; found by the verification suite, sphere_cli/verify/stability.py), i.e.
omega^2 dt^2 + 4 gamma dt <= 4 with gamma = 2 zeta omega (damped_limit).
- one_contact_limit: one contact alone has two modes, normal, omega^2 = k_n/m*, and tangential
  coupled to the rotation of the spheres, omega^2 = 3.5 k_t/m* (1/m* + r_i^2/I_i + r_j^2/I_j =
  3.5/m*), whose damping ratio is sqrt(3.5) zeta; taken over every pair of materials that can
  meet (lightest particles) and every wall. It sets the scale a collision is resolved on:
  dt = "auto" takes dt_safety of it. For Hertz-Mindlin the tangent stiffnesses at
  overlap_tolerance x the smaller radius, and the Rayleigh time.
  A given dt above it is refused. The Rayleigh time pi r sqrt(rho/G)/(0.1631 nu + 0.8766)
  (Li, Xu & Thornton 2005, Powder Technol. 160:219) caps it for Hertz.
- stability_limit: a bound for every packing the scene can reach, from the sum of a sphere's
  contact stiffnesses and dampings at the most contacts it can have (derivation in its
  docstring). dt = "auto" stays below 0.9 of it; a given dt above it is warned of.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from .. import ranks
from ..kernels.contact import (
    BLOCK,
    FIELDS,
    ID_ROWS,
    chunk_pair_forces,
    chunk_pair_forces_serial,
    cross_chunk_pairs,
    pack_pairs,
)
from ..kernels.laws import K_T
from ..kernels.observe.energy import pair_elastic_energy
from ..kernels.serial import use_serial
from ..runtime import last_level_cache_bytes
from ..state import State
from .laws import ContactLaw
from .materials import ContactTables
from .module import Module
from .neighbors import SPRING_ROOM, listed_slots


def rows_across_chunks(nbr, nbr_count, bounds, pieces: int) -> tuple[np.ndarray, np.ndarray]:
    """(rows, cuts): the rows holding pairs whose partner lies beyond the row's chunk (chunk c:
    bounds[c] <= i < bounds[c+1]), as (row, end of its chunk) (R,2) int64, and cuts (pieces+1,)
    int64 into them giving each piece about as many of those pairs (kernels/contact.py,
    cross_chunk_pairs)."""
    if bounds.size == 2:  # one chunk holds every pair
        return np.zeros((0, 2), dtype=np.int64), np.zeros(pieces + 1, dtype=np.int64)
    end = bounds[np.searchsorted(bounds, np.arange(nbr.shape[0]), side="right")]
    pairs = np.count_nonzero(listed_slots(nbr, nbr_count) & (nbr >= end[:, None]), axis=1)
    crossing = np.flatnonzero(pairs)
    rows = np.stack([crossing, end[crossing]], axis=1).astype(np.int64)
    work = np.cumsum(pairs[crossing])
    total = work[-1] if work.size else 0
    cuts = np.searchsorted(work, np.arange(1, pieces) * (total / pieces))
    return rows, np.concatenate(([0], cuts, [crossing.size])).astype(np.int64)


def beyond_cache(state: State) -> bool:
    """True if the arrays a step goes through (the particles', the neighbour list's and its
    springs) outgrow half this process's share of the processor's largest cache
    (the cache over the MPI ranks on this node, sphere_cli/ranks.py), so that each step reads
    them from memory: the pair sweep then prefetches the lines of the listed pairs' partners
    ahead (kernels/contact.py touching_pairs), which only costs where they stay in the cache.
    Half: the step's other arrays (the packed pairs, the blocks, the walls') share the cache
    too. Measured on one thread of a 32 MiB cache (docs/performance.md): 20 000 and 30 000
    settled spheres (8 and 12 MB counted here) stepped 0-7 % slower with the hints, 50 000
    (20 MB) 5-10 % faster and 100 000 1.13-1.22 x; two processes of 50 000 sharing the cache
    20 % faster each, and 100 000 on two ranks 10-20 %."""
    p, nl = state.particles, state.neighbors
    arrays = [getattr(p, name) for name in p.PROGNOSTIC] + [p.vel_pred, p.angvel_pred]
    arrays += [nl.nbr, nl.nbr_count, nl.start, nl.hist, nl.ref_pos]
    world = ranks.current()
    sharing = 1 if world is None else world.node_size
    return sum(a.nbytes for a in arrays) > last_level_cache_bytes() / (2 * sharing)


class PairContactForces(Module):
    name = "contact"

    def __init__(self, tables: ContactTables):
        self.tables = tables
        self.table = np.ascontiguousarray(tables.table)
        self.law_code = tables.law.code  # the kernels' law code (kernels/laws.py)
        self.rolling = tables.rolling
        # per-pair slots (scratch, sized with the neighbour list, used by the pairs across
        # chunks only): force on the first member, n x F_t, and the rolling torque when rolling
        # resistance is on (kernels/contact.py)
        self.width = 9 if self.rolling else 6
        self.slots = np.zeros((0, self.width))
        # per chunk, the block of touching pairs whose law is evaluated in one vectorised loop
        # (kernels/contact.py): inputs and results, each pair's (i, j, spring index), rows waiting
        # for slots
        self.blocks = np.zeros((0, FIELDS * BLOCK))
        self.block_ids = np.zeros((0, ID_ROWS * BLOCK), dtype=np.uint64)
        self.block_rows = np.zeros((0, 2 * BLOCK), dtype=np.int64)
        # the listed pairs in the springs' order, each one's row and partner (pack_pairs), and
        # the list they were made from: its build, rows' arrays and row starts
        self.pair_row = np.zeros(0, dtype=np.int32)
        self.pair_partner = np.zeros(0, dtype=np.int32)
        self.pairs_of = None
        self.pairs_start = np.zeros(0, dtype=np.int64)
        # whether the sweep prefetches its partners (beyond_cache), and the list it was asked for
        self.warm = False
        self.warm_of = None
        self.bounds = np.zeros(2, dtype=np.int64)
        self.bounds_build = -1  # the neighbour-list build the chunk cuts were made for
        # rows with pairs across chunks: (row, end of its chunk), shared evenly between threads
        self.cross_rows = np.zeros((0, 2), dtype=np.int64)
        self.cross_bounds = np.zeros(2, dtype=np.int64)

    def _chunks(self, nl) -> None:
        """One chunk of particles per thread, cut where the listed pairs (plus one per
        particle) are shared evenly, again after each rebuild of the list; the result does not
        depend on the cuts. Slots only when there is more than one chunk."""
        n = nl.nbr.shape[0]
        chunks = max(1, min(numba.get_num_threads(), n))
        if self.bounds.size != chunks + 1 or self.bounds[-1] != n or self.bounds_build != nl.builds:
            work = np.cumsum(np.minimum(nl.nbr_count, nl.nbr.shape[1]) + 1)
            cuts = np.searchsorted(work, np.arange(1, chunks) * (work[-1] / chunks))
            self.bounds = np.concatenate(([0], cuts, [n])).astype(np.int64)
            self.bounds_build = nl.builds
            self.cross_rows, self.cross_bounds = rows_across_chunks(nl.nbr, nl.nbr_count, self.bounds, chunks)
        # one slot per spring index (start[i] + k): as many as the springs' rows, or without
        # friction (no springs) as many as the listed pairs, with the springs' room
        rows = nl.hist.shape[0]
        if not rows:
            pairs = int(nl.start[-1])
            rows = self.slots.shape[0] if self.slots.shape[0] >= pairs else int(SPRING_ROOM * pairs) + 64
        if chunks == 1:
            rows = 0
        if self.slots.shape[0] != rows:
            self.slots = np.zeros((rows, self.width))
        if self.blocks.shape[0] != chunks:
            self.blocks = np.zeros((chunks, FIELDS * BLOCK))
            self.block_ids = np.zeros((chunks, ID_ROWS * BLOCK), dtype=np.uint64)
            self.block_rows = np.zeros((chunks, 2 * BLOCK), dtype=np.int64)
        self._pairs(nl)

    def _pairs(self, nl) -> None:
        """The listed pairs' rows and partners in the springs' order, made again whenever the
        list is not the one they were made from: another build, other row arrays, or other row
        starts (a rank drops its ghosts' pairs from a build in place, moving the starts)."""
        made_of = (nl.builds, id(nl.nbr), id(nl.nbr_count), nl.nbr.shape)
        if made_of == self.pairs_of and np.array_equal(nl.start, self.pairs_start):
            return
        pairs = int(nl.start[-1])
        if self.pair_row.shape[0] < pairs:
            self.pair_row = np.zeros(int(SPRING_ROOM * pairs) + 64, dtype=np.int32)
            self.pair_partner = np.zeros_like(self.pair_row)
        pack_pairs(nl.nbr, nl.nbr_count, nl.start, self.pair_row, self.pair_partner)
        self.pairs_of = made_of
        self.pairs_start = nl.start.copy()

    def forces(self, state: State, spring_dt: float | None = None) -> None:
        """Pair forces at the current positions; the tangential springs grow by the slip over
        `spring_dt` (default: one step; 0 for the forces of the initial state)."""
        cross, pairs = self.kernel_arguments(state, spring_dt)
        if cross is not None:
            cross_chunk_pairs(*cross)
        (chunk_pair_forces_serial if use_serial() else chunk_pair_forces)(*pairs)

    def kernel_arguments(self, state: State, spring_dt: float | None = None) -> tuple:
        """The arguments of cross_chunk_pairs (None with one chunk: nothing crosses) and of
        chunk_pair_forces (kernels/contact.py; also for kernels/steps.py), valid until the
        neighbour list is rebuilt or the thread count changes."""
        p, box, nl = state.particles, state.box, state.neighbors
        dt = state.clock.dt
        spring = dt if spring_dt is None else spring_dt
        self._chunks(nl)
        if self.warm_of is not self.pairs_of:  # the arrays' sizes change with the list only
            self.warm, self.warm_of = beyond_cache(state), self.pairs_of
        common = (
            p.pos,
            p.vel,
            p.angvel,
            p.vel_pred,
            p.angvel_pred,
            p.radius,
            p.inv_mass,  # the reduced mass follows the motion the integrator applies
            p.inv_inertia,
            p.material,
            nl.nbr,
            nl.nbr_count,
            nl.start,
            nl.hist,
            self.table,
            self.law_code,
            self.rolling,
            box.length,
            box.periodic,
            spring,
            dt,
        )
        cross = None
        if self.bounds.size > 2:
            cross = (*common, self.cross_rows, self.cross_bounds, self.slots, self.blocks, self.block_ids)
        return cross, (
            *common,
            nl.rev,
            nl.rev_count,
            self.pair_row,
            self.pair_partner,
            self.warm,
            box.body_acc,
            p.mass,
            self.bounds,
            self.slots,
            self.blocks,
            self.block_ids,
            self.block_rows,
            p.force,
            p.torque,
        )

    def elastic_energy(self, state: State) -> tuple[float, int]:
        p, box, nl = state.particles, state.box, state.neighbors
        energy, pairs = pair_elastic_energy(
            p.pos,
            p.radius,
            p.material,
            nl.nbr,
            nl.nbr_count,
            nl.start,
            nl.hist,
            self.table,
            self.law_code,
            box.length,
            box.periodic,
        )
        return float(energy), int(pairs)


def scheme_factor(zeta: float) -> float:
    """omega dt at the stability limit of velocity Verlet with the dashpot at the predicted
    velocity: 2 (sqrt(1 + 4 zeta^2) - 2 zeta) (2 undamped)."""
    return 2.0 * (math.sqrt(1.0 + 4.0 * zeta * zeta) - 2.0 * zeta)


def verlet_limit(kn: float, kt: float, zeta: float, m_eff: float) -> float:
    """Stability limit [s] of a contact with normal and tangential stiffness kn, kt [N/m], damping
    ratio zeta and reduced mass m_eff [kg]: the smaller of its normal and rotation-coupled
    tangential modes (inf without stiffness or mass)."""
    if not math.isfinite(m_eff):
        return math.inf
    limit = math.inf
    if kn > 0.0:
        limit = scheme_factor(zeta) / math.sqrt(kn / m_eff)
    if kt > 0.0:
        limit = min(limit, scheme_factor(math.sqrt(3.5) * zeta) / math.sqrt(3.5 * kt / m_eff))
    return limit


def row_limit(row: np.ndarray, law: ContactLaw, m_eff: float, r_eff: float, delta: float) -> float:
    """dt_contact of one table row (kernels/laws.py) at reduced mass m_eff [kg], with the
    tangent stiffnesses at effective radius r_eff [m] and overlap delta [m]."""
    stiffness = law.normal_stiffness(row, r_eff, delta)
    return verlet_limit(stiffness, row[K_T] * law.scale(r_eff, delta), law.damping_ratio(row), m_eff)


def _lightest(material: np.ndarray, mass: np.ndarray, materials: int) -> dict[int, np.ndarray]:
    """Material id -> the indices of its two lightest particles (one if it has one), for the
    materials particles are made of."""
    lightest = {}
    for a in range(materials):
        members = np.flatnonzero(material == a)
        if members.size:
            lightest[a] = members[np.argsort(mass[members], kind="stable")[:2]]
    return lightest


def coordination_bound(radius: float, smallest: float, others: int) -> int:
    """The most bodies that can touch a sphere of `radius` at once, when no sphere is smaller
    than `smallest` (a plane wall counts as a sphere of infinite radius) and `others` bodies
    exist: 12, the kissing number, if none is smaller than it; else the spherical caps of
    half-angle asin(smallest/(radius + smallest)) that its touching neighbours hide of it, which
    cannot overlap, cover at most the whole sphere: 2/(1 - cos theta)."""
    if radius <= smallest:
        most = 12
    else:
        sin_theta = smallest / (radius + smallest)
        most = math.floor(2.0 / (1.0 - math.sqrt(1.0 - sin_theta * sin_theta)))
    return max(1, min(most, others))


def damped_limit(omega2: float, gamma: float) -> float:
    """Largest dt [s] with omega2 dt^2 + 4 gamma dt <= 4: velocity Verlet with the dashpot at the
    predicted velocity on a mode of omega^2 = omega2 [1/s^2] and c/m = 2 zeta omega = gamma [1/s]
    (the limit omega dt <= 2 (sqrt(1 + 4 zeta^2) - 2 zeta) written for omega and gamma)."""
    if omega2 <= 0.0:
        return math.inf
    if not (omega2 < math.inf and gamma < math.inf):  # overflowed (a mass of 1e-308 kg): no step
        return 0.0
    return 2.0 * (math.sqrt(gamma * gamma + omega2) - gamma) / omega2


def stability_limit(
    tables: ContactTables,
    radius: np.ndarray,
    mass: np.ndarray,
    material: np.ndarray,
    overlap: float,
    wall_faces: list[str],
) -> tuple[float, str]:
    """(stability bound of the contacts [s], what sets it); inf if no contact can occur.
    overlap: the largest initial overlap as a fraction of the smaller radius.

    A bound for every packing the scene can reach (user guide, section 2). With M the masses
    and inertias and K, C the stiffness and damping matrices of all contacts, contact c adds
    B_c^T S_c B_c to K (B_c: the velocity of its contact point, S_c = diag(k_n, k_t, k_t)).
    With y = M^1/2 x and Young's inequality |a + b|^2 <= (1 + t)|a|^2 + (1 + 1/t)|b|^2 at
    t = m_i/m_j,
        x^T K x = sum_c |S_c^1/2 (B_ci x_i + B_cj x_j)|^2 <= sum_c kappa_c/m*_c (|y_i|^2 + |y_j|^2),
    since |S_c^1/2 B_ci M_i^-1/2|^2 = kappa_c/m_i; so the fastest mode has
        omega^2 <= max_i sum_{c at i} kappa_c/m*_c        (m*_c = m_i against a wall),
    and the damping rate gamma <= max_i sum_c d_c/sqrt(m*_c) likewise (c = d sqrt(m*)). A
    sphere of material a touches at most coordination_bound bodies, each contact at most the
    largest kappa/m* (and d/sqrt(m*)) of a pair with the lightest sphere of any material or of
    a wall; the lightest sphere of a is the worst (the count grows as r^2, the mass as r^3).
    For two equal spheres this is the limit of their one contact; for a chain it is reached.
    For Hertz the stiffnesses are the tangent ones at the overlap `overlap` x the radius (the
    Rayleigh time, an impact criterion, is in one_contact_limit)."""
    law = tables.law
    limits: list[tuple[float, str]] = []
    lightest = _lightest(material, mass, len(tables.names))
    smallest = float(radius.min()) if radius.size else 0.0
    others = radius.size - 1 + len(wall_faces)
    for a, first in lightest.items():
        i = int(first[0])
        r, m = float(radius[i]), float(mass[i])
        omega2 = gamma = 0.0  # the largest kappa/m* and d/sqrt(m*) of a contact at it
        for b, second in lightest.items():
            if b == a and first.size < 2:  # no partner of its own material
                continue
            m_b = float(mass[second[0]])  # the lightest partner: the smallest m*
            r_b = float(radius[material == b].max())  # the largest: the stiffest Hertz contact
            k, d = law.coefficients(tables.table[a, b], r * r_b / (r + r_b), overlap * r)
            m_eff = m * m_b / (m + m_b)
            omega2, gamma = max(omega2, k / m_eff), max(gamma, d / math.sqrt(m_eff))
        for w in range(len(wall_faces)):
            k, d = law.coefficients(tables.wall_table[w, a], r, overlap * r)
            omega2, gamma = max(omega2, k / m), max(gamma, d / math.sqrt(m))
        contacts = coordination_bound(r, smallest, others)
        value = damped_limit(contacts * omega2, contacts * gamma)
        if value < math.inf:
            limits.append(
                (
                    value,
                    f"{law.label} contacts of the lightest particle of {tables.label(a)} (r = {r:.4g} m), "
                    f"held by up to {contacts} bodies at once: omega^2 dt^2 + 4 gamma dt <= 4 with "
                    f"omega^2 = {contacts} x {omega2:.4g} s^-2, gamma = {contacts} x {gamma:.4g} s^-1"
                    + law.tangent_note(overlap),
                )
            )
    if not limits:
        return math.inf, "no contact can occur"
    value, what = min(limits, key=lambda item: item[0])
    return float(value), what


# overlaps of tens of per cent of a radius are outside what a soft-sphere contact law describes
# (they let spheres pass through one another and through walls): a particle's overlap under its
# own weight beyond this share of its radius is warned of (it lasts, and the particles under it
# carry more) ...
WEIGHT_OVERLAP = 0.1
# ... and in a head-on impact at its initial speed, the dashpot left out, beyond this share (an
# upper bound of a passing overlap: the verification's impacts reach 0.1 of it with 1e-3 accuracy)
IMPACT_OVERLAP = 0.25


def _least_overlap(
    tables: ContactTables, radius, mass, material, wall_faces, a: int, r: float, load: tuple
) -> tuple[float, str] | None:
    """(the least overlap of a particle of material a and radius r over the supports it can
    meet, any wall or the largest particle of any material (the stiffest, for Hertz), and which
    support) under `load`: ("weight", force [N]) resting, or ("impact", mass [kg], speed [m/s])
    striking it head-on. None if it can meet nothing."""
    law = tables.law

    def overlap(row, r_eff: float, partner_mass: float) -> float:
        if load[0] == "weight":
            return law.static_overlap(row, r_eff, load[1])
        m = load[1]
        m_eff = m if partner_mass == math.inf else m * partner_mass / (m + partner_mass)  # a wall: m
        return law.impact_overlap(row, r_eff, m_eff, load[2])

    supports = [
        (overlap(tables.wall_table[w, a], r, math.inf), f"the {face} wall")
        for w, face in enumerate(wall_faces)
    ]
    for b in range(len(tables.names)):
        partners = np.flatnonzero(material == b)
        if partners.size > (1 if b == a else 0):
            k = int(partners[np.argmax(radius[partners])])
            r_b = float(radius[k])
            supports.append(
                (
                    overlap(tables.table[a, b], r * r_b / (r + r_b), float(mass[k])),
                    f"a particle of {tables.label(b)} (r = {r_b:.4g} m)",
                )
            )
    return min(supports, key=lambda item: item[0]) if supports else None


def load_overlaps(
    tables: ContactTables,
    radius: np.ndarray,
    mass: np.ndarray,
    speed: np.ndarray,
    material: np.ndarray,
    wall_faces: list[str],
    gravity: float,
    fluid_density: float = 0.0,
) -> list[tuple[int, str]]:
    """(material, what) for each load on a material's particles that makes one
    overlap the stiffest support it can have (_least_overlap) too deeply: the heaviest particle
    resting under its weight (less its buoyancy in a fluid of `fluid_density` [kg/m^3]; gravity
    [m/s^2]), beyond WEIGHT_OVERLAP x its radius, and the particle of the most kinetic energy
    (speed [m/s] each) striking it head-on, the dashpot left out (the most it can overlap),
    beyond IMPACT_OVERLAP x its radius: contacts too soft for the load."""
    law = tables.law
    found = []
    for a in range(len(tables.names)):
        members = np.flatnonzero(material == a)
        if members.size == 0:
            continue
        of = "" if tables.names[a] == "" else " of " + tables.label(a)
        i = int(members[np.argmax(mass[members])])
        r, m = float(radius[i]), float(mass[i])
        weight = m * gravity * (1.0 - fluid_density / tables.materials[a].density)
        least = None  # a buoyant particle rests on nothing (and (negative)^(2/3) is complex)
        if weight > 0.0:
            least = _least_overlap(tables, radius, mass, material, wall_faces, a, r, ("weight", weight))
        if least is not None and least[0] > WEIGHT_OVERLAP * r:
            what = (
                f"the heaviest particle{of} (r = {r:.4g} m, m = {m:.4g} kg) resting on {least[1]} overlaps "
                f"it by {least[0]:.3g} m, {least[0] / r:.3g} x its radius, under its own weight"
            )
            found.append((a, f"{what} ({law.label} contact)"))
        j = int(members[np.argmax(mass[members] * speed[members] ** 2)])
        r, m, v = float(radius[j]), float(mass[j]), float(speed[j])
        least = _least_overlap(tables, radius, mass, material, wall_faces, a, r, ("impact", m, v))
        if v > 0.0 and least is not None and least[0] > IMPACT_OVERLAP * r:
            what = (
                f"the particle{of} of the most kinetic energy (r = {r:.4g} m, m = {m:.4g} kg, {v:.4g} m/s "
                f"at the start) striking {least[1]} head-on would overlap it by up to {least[0]:.3g} m, "
                f"{least[0] / r:.3g} x its radius"
            )
            found.append((a, f"{what} ({law.label} contact)"))
    return found


def one_contact_limit(
    tables: ContactTables,
    radius: np.ndarray,
    mass: np.ndarray,
    material: np.ndarray,
    overlap: float,
    wall_faces: list[str],
) -> tuple[float, str]:
    """(smallest stability limit of one contact alone, of any pair of materials or wall [s], what
    sets it): the scale a collision is resolved on (dt = "auto" takes dt_safety of it), not a
    bound for spheres held by several contacts (stability_limit). inf if no contact can occur.
    overlap: the largest initial overlap as a fraction of the smaller radius."""
    law = tables.law
    lightest = _lightest(material, mass, len(tables.names))
    contacts: list[tuple[float, str]] = []
    for a, first in lightest.items():
        for b, second in lightest.items():
            if b < a:
                continue
            if a == b:
                if first.size < 2:
                    continue
                i, j = int(first[0]), int(first[1])
            else:
                i, j = int(first[0]), int(second[0])
            m_eff = float(mass[i] * mass[j] / (mass[i] + mass[j]))
            r_eff = float(radius[i] * radius[j] / (radius[i] + radius[j]))
            delta = overlap * float(min(radius[i], radius[j]))
            what = (
                f"{law.label} contact of {tables.label(a)}"
                + ("" if a == b else f" with {tables.label(b)}")
                + ", lightest pair"
            )
            contacts.append((row_limit(tables.table[a, b], law, m_eff, r_eff, delta), what))
        for w, face in enumerate(wall_faces):
            i = int(first[0])
            row = tables.wall_table[w, a]
            value = row_limit(row, law, float(mass[i]), float(radius[i]), overlap * radius[i])
            what = f"{law.label} contact of the lightest particle of {tables.label(a)} with the {face} wall"
            contacts.append((value, what))
    note = law.limit_note(overlap)
    limits = law.impact_limits(tables, lightest, radius) + [(v, w + note) for v, w in contacts]
    if not limits:
        return math.inf, "no contact can occur"
    value, what = min(limits, key=lambda item: item[0])
    return float(value), what
