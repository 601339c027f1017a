"""Stability suite: stiff and extreme input (verification group E); the DEM cases here, the
fluids' in fluid_stability.py.

For each case: what the program did (refused before the run, ran stably, reported a numerical
failure with step, time and particle), and, where a persistent contact makes the question
sharp, the largest stable dt found, as a multiple of the limit the builder enforces (the
stiffest contact and lightest pair, physics/contact.py; the theory of each mode is stated with
its case). The builder refuses any dt above that limit, so the search sets the trial dt on the
built scene directly, to find where the scheme itself goes unstable: a ratio >= 1 means every
dt the program accepts is stable.
A silent NaN or a plausible wrong answer is a failure.
"""

from __future__ import annotations

import math
import re
import tempfile
import textwrap
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..errors import CaseError, NumericalError, SphereError
from ..physics.observe.energy import observables
from ..physics.restitution import linear_damping_ratio
from ..simulation import advance, check_stable
from .scenes import case_text, linear_contact, particle_csv, particle_scene, sphere_mass, toml_table

R = 1.0e-3
DENSITY = 2500.0
MASS = sphere_mass(R, DENSITY)
KN = 1.0e3
G = 9.81
PROBE_STEPS = 4000  # steps per trial of the dt search (>= 1000 periods near the limit)
PERTURB = 1.0e-3  # initial amplitude of the probed oscillation, in static overlaps


@dataclass(frozen=True)
class StabilityCase:
    name: str
    title: str
    expected: str  # what the program must do: "refused", "ran", "reported"
    run: Callable[[bool], dict]  # (quick) -> result fields


STABILITY: dict[str, StabilityCase] = {}


def _register(case: StabilityCase) -> None:
    STABILITY[case.name] = case


# ----------------------------------------------------------------------- the dt search


GROWTH = 50.0  # an oscillation this many times its initial amplitude counts as unstable


def grows(scene, coordinate: Callable[[], float], amplitude: float, steps: int = PROBE_STEPS) -> bool:
    """True if the oscillation of `coordinate` (a deviation from equilibrium, started with
    `amplitude`) grows: beyond GROWTH x amplitude, or larger over the second half of the run than
    twice over the first, or the state turns non-finite, or the stability guard fires. A stable
    undamped oscillation keeps its amplitude (Verlet inflates it by 1/sqrt(1 - (omega dt/2)^2),
    50x only within 2e-4 of the limit), a damped one decays; past the limit it grows
    geometrically until a nonlinearity (contact lost, Coulomb cap) bounds it, which the small
    start (1e-3 of the static overlap) leaves far above GROWTH x amplitude."""
    half = steps // 2
    first = second = 0.0
    try:
        for n in range(steps):
            advance(scene, 1)
            x = abs(coordinate())
            if not math.isfinite(x) or x > GROWTH * amplitude:
                return True
            if n < half:
                first = max(first, x)
            else:
                second = max(second, x)
            if (n + 1) % 100 == 0:
                check_stable(scene)
    except (NumericalError, FloatingPointError, OverflowError):
        return True
    return second > 2.0 * first


def largest_stable_ratio(
    build: Callable[[], object],
    coordinate: Callable[[object], float],
    amplitude: float,
    lo: float = 0.5,
    hi: float = 3.0,
    iterations: int = 14,
) -> dict:
    """Bisect r = dt/dt_limit between lo (stable) and hi (unstable) with `grows` as the test.
    build() returns a scene at dt = "auto"; its dt_limit is the theory the ratio refers to."""
    trials = 0

    def unstable(ratio: float) -> tuple[bool, float]:
        nonlocal trials
        trials += 1
        scene = build()
        scene.state.clock.dt = ratio * scene.dt_limit
        return grows(scene, lambda: coordinate(scene), amplitude), scene.dt_limit

    lo_bad, limit = unstable(lo)
    if lo_bad:
        return {"ratio": None, "detail": f"unstable already at {lo} x the limit", "theory_dt_s": limit}
    hi_bad, _ = unstable(hi)
    if not hi_bad:
        return {
            "ratio": hi,
            "detail": f"stable up to {hi} x the limit (searched no further)",
            "theory_dt_s": limit,
        }
    for _ in range(iterations):
        mid = 0.5 * (lo + hi)
        if unstable(mid)[0]:
            hi = mid
        else:
            lo = mid
    return {
        "ratio": lo,
        "detail": f"stable at {lo:.4f}, unstable at {hi:.4f} x the limit ({trials} trial runs)",
        "theory_dt_s": limit,
    }


# ---------------------------------------------------------- persistent contacts (dt limit)


def scheme_limit(omega: float, zeta: float) -> float:
    """Stability limit [s] of this code's velocity Verlet on a damped linear mode (omega, zeta)
    with the dashpot at the predicted velocity v_n + dt a_n: the amplification matrix of
    (x, v, a) has det(M + I) = 4 - h^2 - 8 zeta h (h = omega dt), so an eigenvalue crosses -1 at
    h = 2 (sqrt(1 + 4 zeta^2) - 2 zeta): the central-difference limit with zeta doubled."""
    return 2.0 * (math.sqrt(1.0 + 4.0 * zeta * zeta) - 2.0 * zeta) / omega


def _resting_sphere(e: float, mode: str, kt: float | None = None):
    """A sphere resting on a wall under gravity at its static overlap, set oscillating with a
    small amplitude (PERTURB x the static overlap): normally (mode "normal") or tangentially
    (mode "tangential", mu = 10 keeps it stuck). Returns (build, coordinate, amplitude, omega,
    zeta) of the excited mode: the tangential one, coupled to rolling, has omega^2 = 3.5 k_t/m
    and damping ratio sqrt(3.5) zeta (c_t = 2 zeta sqrt(k_t m) acts on u' = -3.5 F_t/m)."""
    static = MASS * G / KN
    kt_value = 2.0 / 7.0 * KN if kt is None else kt
    if mode == "normal":
        omega = math.sqrt(KN / MASS)
        amplitude = PERTURB * static
        vel = [[0.0, 0.0, amplitude * omega]]
        contact = linear_contact(KN, e, 0.5, kt=kt)
        coordinate = _normal_deviation
    else:
        omega = math.sqrt(3.5 * kt_value / MASS)
        amplitude = PERTURB * static * omega  # of the slip velocity
        vel = [[amplitude, 0.0, 0.0]]
        contact = linear_contact(KN, e, 10.0, kt=kt)
        coordinate = _slip

    def build():
        return particle_scene(
            [[0.05, 0.05, R - static]], R, vel, contact=contact, gravity=(0.0, 0.0, -G), walls=["z-"]
        )

    return build, coordinate, amplitude, omega


def _normal_deviation(scene) -> float:
    return float(scene.state.particles.pos[0, 2]) - (R - MASS * G / KN)


def _slip(scene) -> float:
    p = scene.state.particles
    return float(p.vel[0, 0] - R * p.angvel[0, 1])


def _dt_limit_case(e: float, mode: str, quick: bool, kt: float | None = None) -> dict:
    build, coordinate, amplitude, omega = _resting_sphere(e, mode, kt)
    scene = build()
    zeta = linear_damping_ratio(e) * (math.sqrt(3.5) if mode == "tangential" else 1.0)
    predicted = scheme_limit(omega, zeta) / scene.dt_limit
    auto = scene.state.clock.dt / scene.dt_limit  # dt = "auto" as a share of the limit
    search = largest_stable_ratio(build, coordinate, amplitude, lo=0.25, iterations=10 if quick else 14)
    ratio = search["ratio"]
    return {
        "action": "ran",
        "theory": (
            f"this mode (omega = {omega:.5g} rad/s, zeta = {zeta:.4f}) under velocity Verlet with the "
            f"dashpot at v_n + dt a_n: 2 (sqrt(1 + 4 zeta^2) - 2 zeta)/omega = {predicted:.4f} x the "
            f"builder's limit ({scene.dt_limit_reason})"
        ),
        "theory_dt_s": scene.dt_limit,
        "scheme_limit_ratio": predicted,
        "largest_stable_ratio": ratio,
        "detail": search["detail"],
        "checks": [
            {
                "check": "every dt the builder accepts is stable (largest stable ratio >= 0.99)",
                "passed": ratio is not None and ratio >= 0.99,
                "detail": search["detail"],
            },
            {
                "check": f"dt = auto ({auto:.3g} x the limit) is stable",
                "passed": ratio is not None and ratio >= auto,
                "detail": f"largest stable ratio {ratio}",
            },
            {
                "check": "the measured limit matches the scheme's closed form (2 %)",
                "passed": ratio is not None and abs(ratio / predicted - 1.0) <= 0.02,
                "detail": f"measured {ratio}, closed form {predicted:.4f}",
            },
        ],
    }


def _oscillation_checks(error, peak, amplitude, energy_dev, scale, ratio, search) -> list[dict]:
    """The checks every dt = auto oscillation case shares: it runs, stays bounded, conserves
    energy (e = 1), and every dt the builder accepts is stable."""
    return [
        {
            "check": "dt = auto runs without a numerical failure",
            "passed": error is None,
            "detail": error or "",
        },
        {
            "check": "the oscillation stays bounded (peak <= 1.1 x initial amplitude)",
            "passed": peak <= 1.1 * amplitude,
            "detail": f"{peak / amplitude:.4f}",
        },
        {
            "check": "energy conserved to 1e-2 of the oscillation energy (e = 1)",
            "passed": energy_dev <= 1e-2 * scale,
            "detail": f"{energy_dev / scale:.3g}",
        },
        {
            "check": "every dt the builder accepts is stable (largest stable ratio >= 0.99)",
            "passed": ratio is not None and ratio >= 0.99,
            "detail": search["detail"],
        },
    ]


_register(
    StabilityCase(
        "stability-limit-normal-elastic",
        "contact limit, normal mode, e = 1 (sphere resting on a wall): theory 2/omega0",
        "ran",
        lambda quick: _dt_limit_case(1.0, "normal", quick),
    )
)
_register(
    StabilityCase(
        "stability-limit-tangential-elastic",
        "contact limit, tangential (rolling-coupled) mode, k_t = k_n, e = 1: theory 2/sqrt(3.5 k_t/m)",
        "ran",
        lambda quick: _dt_limit_case(1.0, "tangential", quick, kt=KN),
    )
)
_register(
    StabilityCase(
        "stability-limit-normal-damped",
        "contact limit, normal mode, e = 0.5 (dashpot at the predicted velocity)",
        "ran",
        lambda quick: _dt_limit_case(0.5, "normal", quick),
    )
)
_register(
    StabilityCase(
        "stability-limit-tangential-damped",
        "contact limit, tangential mode, default k_t = 2/7 k_n, e = 0.5",
        "ran",
        lambda quick: _dt_limit_case(0.5, "tangential", quick),
    )
)


# ------------------------------------------------------------------- dt 3x above the limit


def _refusal(build: Callable[[], object]) -> tuple[SphereError | None, object]:
    try:
        return None, build()
    except SphereError as exc:
        return exc, None


def dt_above_limit(quick: bool) -> dict:
    """A case asking for dt = 3 x the contact limit must be refused before the run, naming the
    key and the limit."""
    static = MASS * G / KN
    common = {"contact": linear_contact(KN, 0.5, 0.5), "gravity": (0.0, 0.0, -G), "walls": ["z-"]}
    auto = particle_scene([[0.05, 0.05, R - static]], R, **common)
    limit = auto.dt_limit
    exc, _ = _refusal(lambda: particle_scene([[0.05, 0.05, R - static]], R, dt=3.0 * limit, **common))
    message = str(exc) if exc is not None else ""
    return {
        "action": "refused" if isinstance(exc, CaseError) else "ran",
        "exit_code": getattr(exc, "exit_code", 0),
        "theory": auto.dt_limit_reason,
        "theory_dt_s": limit,
        "largest_stable_ratio": None,
        "detail": _first_line(message) or "accepted dt = 3 x the limit",
        "checks": [
            {
                "check": "refused with a CaseError (exit 65)",
                "passed": isinstance(exc, CaseError),
                "detail": "",
            },
            {
                "check": "the message names simulation.dt and the limit",
                "passed": "simulation.dt" in message and f"{limit:.4g}" in message,
                "detail": _first_line(message),
            },
        ],
    }


_register(
    StabilityCase(
        "stability-dt-3x-limit",
        "dt = 3 x the contact limit in the case file",
        "refused",
        dt_above_limit,
    )
)


# ------------------------------------------------- mass ratio 1e4 (reduced-mass pitfall)


SMALL_R = 0.5e-3
BIG_R = SMALL_R * 1.0e4 ** (1.0 / 3.0)  # mass ratio 1e4: omega^2 of the pair 1e4 x the big one's wall


def _stack(e: float, perturb: float):
    """A small sphere resting on a big one (mass ratio 1e4) resting on a wall, gravity on, at
    the static overlaps, the small one set oscillating (perturb x its static overlap)."""
    m_small, m_big = sphere_mass(SMALL_R, DENSITY), sphere_mass(BIG_R, DENSITY)
    d_wall = (m_small + m_big) * G / KN
    d_pair = m_small * G / KN
    z_big = BIG_R - d_wall
    z_small = z_big + BIG_R + SMALL_R - d_pair
    m_eff = m_small * m_big / (m_small + m_big)
    w = perturb * d_pair * math.sqrt(KN / m_eff)
    pos = [[0.05, 0.05, z_big], [0.05, 0.05, z_small]]

    def build(dt="auto"):
        return particle_scene(
            pos,
            [BIG_R, SMALL_R],
            [[0.0, 0.0, 0.0], [0.0, 0.0, w]],
            contact=linear_contact(KN, e, 0.5),
            gravity=(0.0, 0.0, -G),
            walls=["z-"],
            upper=(0.1, 0.1, 0.1),
            dt=dt,
        )

    def pair_deviation(scene) -> float:
        p = scene.state.particles
        return float(BIG_R + SMALL_R - (p.pos[1, 2] - p.pos[0, 2]) - d_pair)

    return build, pair_deviation, m_small, m_big


def mass_ratio(quick: bool) -> dict:
    """Two species of mass ratio 1e4 in persistent contact (the pair's omega^2 is 1e4 x that of
    the big sphere on the wall): dt = "auto" must take the limit from the reduced mass of the
    lightest pair; it runs stably (and conserves energy, e = 1), and the largest stable dt is
    compared with that limit. One material: only the masses differ (stiffness ratios: below)."""
    build, deviation, m_small, m_big = _stack(1.0, 0.1)
    scene = build()
    e0 = observables(scene)
    scale = e0["kinetic_energy"] + e0["elastic_energy"]
    steps = 20000 if not quick else 5000
    error = None
    peak = 0.0
    energy_dev = 0.0
    try:
        for n in range(steps):
            advance(scene, 1)
            peak = max(peak, abs(deviation(scene)))
            if (n + 1) % 100 == 0:
                check_stable(scene)
                energy_dev = max(energy_dev, abs(observables(scene)["total_energy"] - e0["total_energy"]))
    except NumericalError as exc:
        error = str(exc)
    probe_build, probe_deviation, _, _ = _stack(1.0, PERTURB)
    search = largest_stable_ratio(
        probe_build, probe_deviation, PERTURB * m_small * G / KN, iterations=10 if quick else 14
    )
    m_eff = m_small * m_big / (m_small + m_big)
    mean_limit = 2.0 / math.sqrt(KN / (0.5 * (m_small + m_big)))
    amplitude = 0.1 * m_small * G / KN
    ratio = search["ratio"]
    return {
        "action": "ran" if error is None else "reported",
        "theory": "2/omega, omega^2 = k_n/m* of the lightest pair (m* = m_s m_b/(m_s + m_b))",
        "theory_dt_s": search["theory_dt_s"],
        "largest_stable_ratio": ratio,
        "detail": (
            f"dt = auto = {scene.state.clock.dt:.3g} s ran {steps} steps: pair oscillation peak "
            f"{peak / amplitude:.3f} x its initial amplitude, energy error {energy_dev / scale:.2e} of "
            f"the oscillation energy; a limit from the mean mass would be "
            f"{mean_limit / (2.0 / math.sqrt(KN / m_eff)):.0f} x too large. {search['detail']}"
        ),
        "checks": _oscillation_checks(error, peak, amplitude, energy_dev, scale, ratio, search),
    }


_register(
    StabilityCase(
        "stability-mass-ratio-1e4",
        "two species of mass ratio 1e4 stacked on a wall (reduced-mass pitfall), dt = auto",
        "ran",
        mass_ratio,
    )
)


# ------------------------------------------------------- stiffness ratio 1e4 (materials)


HARD_E, SOFT_E, NU = 7.0e10, 7.0e6, 0.3  # Pa: Young's moduli 1e4 apart (Hertz)
HARD_K, SOFT_K = 1.0e5, 1.0e1  # N/m: stiffnesses 1e4 apart (linear)


def _two_species(law: str, order: tuple[int, int], perturb: float):
    """Two equal spheres of materials "soft" and "hard" (stiffness 1e4 apart) stacked on a rigid
    wall, gravity on, at their static overlaps; `order` lists the particles bottom first (the
    material of each particle is drawn by particles.seed). The bottom sphere is set oscillating
    (perturb x its wall overlap)."""
    if law == "linear":
        contact = {"model": "linear", "restitution": 1.0, "friction": 0.5}
        soft = {"name": "soft", "density": DENSITY, "normal_stiffness": SOFT_K}
        hard = {"name": "hard", "density": DENSITY, "normal_stiffness": HARD_K}
    else:
        contact = {"model": "hertz-mindlin", "restitution": 1.0, "friction": 0.5, "poisson_ratio": NU}
        soft = {"name": "soft", "density": DENSITY, "youngs_modulus": SOFT_E}
        hard = {"name": "hard", "density": DENSITY, "youngs_modulus": HARD_E}
    materials = "".join(toml_table("materials", m, array=True) for m in (soft, hard))

    def overlap(force: float, k: float, r_eff: float) -> float:
        if law == "linear":
            return force / k
        return (force / (4.0 / 3.0 * k * math.sqrt(r_eff))) ** (2.0 / 3.0)

    return contact, materials, overlap


def stiffness_ratio(law: str, quick: bool) -> dict:
    """Two species whose stiffness differs by 1e4 (linear k_n or Hertz E), the hard one resting
    on the wall under the soft one: dt = "auto" must follow the stiffest possible contact (hard
    on the wall) and run stably, conserving energy (e = 1); the largest stable dt of the hard
    sphere's mode is compared with the builder's limit."""
    contact, materials, overlap = _two_species(law, (0, 1), PERTURB)
    weight = MASS * G
    if law == "linear":
        k_wall, k_pair = HARD_K, 2.0 * HARD_K * SOFT_K / (HARD_K + SOFT_K)
        omega = math.sqrt(HARD_K / MASS)
    else:
        e_hard = HARD_E / (1.0 - NU**2)
        k_wall = e_hard
        k_pair = 1.0 / ((1.0 - NU**2) / HARD_E + (1.0 - NU**2) / SOFT_E)
        omega = math.sqrt(2.0 * e_hard * math.sqrt(R * overlap(2.0 * weight, k_wall, R)) / MASS)
    d_wall = overlap(2.0 * weight, k_wall, R)
    d_pair = overlap(weight, k_pair, 0.5 * R)
    z = [R - d_wall, R - d_wall + 2.0 * R - d_pair]

    def build(perturb: float, flip: bool = False):
        pos = [[0.05, 0.05, z[0]], [0.05, 0.05, z[1]]]
        vel = [[0.0, 0.0, perturb * d_wall * omega], [0.0, 0.0, 0.0]]
        if flip:
            pos, vel = pos[::-1], vel[::-1]
        return particle_scene(
            pos,
            R,
            vel,
            contact=contact,
            density=None,
            extra_particles={"material": {"soft": 0.5, "hard": 0.5}},
            extra_tables=materials,
            gravity=(0.0, 0.0, -G),
            walls=["z-"],
        )

    # the material of each particle comes from particles.seed: put the hard one at the bottom
    flip = int(build(PERTURB).state.particles.material[0]) != 1

    def bottom(scene) -> float:
        return int(np.argmin(scene.state.particles.pos[:, 2]))

    def deviation(scene) -> float:
        return float(scene.state.particles.pos[bottom(scene), 2] - z[0])

    scene = build(0.1, flip)
    hard_below = int(scene.state.particles.material[bottom(scene)]) == 1
    e0 = observables(scene)
    scale = e0["kinetic_energy"] + e0["elastic_energy"]
    steps = 5000 if quick else 20000
    error, peak, energy_dev = None, 0.0, 0.0
    try:
        for n in range(steps):
            advance(scene, 1)
            peak = max(peak, abs(deviation(scene)))
            if (n + 1) % 100 == 0:
                check_stable(scene)
                energy_dev = max(energy_dev, abs(observables(scene)["total_energy"] - e0["total_energy"]))
    except NumericalError as exc:
        error = str(exc)
    amplitude = 0.1 * d_wall
    search = largest_stable_ratio(
        lambda: build(PERTURB, flip),
        deviation,
        PERTURB * d_wall,
        lo=0.25,
        hi=3.0 if law == "linear" else 100.0,
        iterations=10 if quick else 14,
    )
    ratio = search["ratio"]
    return {
        "action": "ran" if error is None else "reported",
        "theory": scene.dt_limit_reason,
        "theory_dt_s": search["theory_dt_s"],
        "largest_stable_ratio": ratio,
        "detail": (
            f"{law}: dt = auto = {scene.state.clock.dt:.3g} s ran {steps} steps: the hard sphere's "
            f"oscillation peaked at {peak / amplitude:.3f} x its initial amplitude, energy error "
            f"{energy_dev / scale:.2e} of the oscillation energy. {search['detail']}"
        ),
        "checks": [
            {"check": "the hard sphere rests on the wall", "passed": hard_below, "detail": ""},
            *_oscillation_checks(error, peak, amplitude, energy_dev, scale, ratio, search),
        ],
    }


_register(
    StabilityCase(
        "stability-stiffness-ratio-linear",
        "two species with k_n 1e4 apart (linear), the stiff one on a wall under the soft one, dt = auto",
        "ran",
        lambda quick: stiffness_ratio("linear", quick),
    )
)
_register(
    StabilityCase(
        "stability-stiffness-ratio-hertz",
        "two species with E 1e4 apart (Hertz-Mindlin), the stiff one on a wall under the soft one, dt = auto",
        "ran",
        lambda quick: stiffness_ratio("hertz", quick),
    )
)


# ----------------------------------------------------------------------- huge overlaps


def huge_overlap(quick: bool) -> dict:
    """Initial overlaps beyond particles.overlap_tolerance are refused, naming the key (pair and
    wall); an overlap just inside the largest tolerance (0.45 R with tolerance 0.5) is accepted
    and, at dt = auto and e = 1, released without loss or gain of energy (linear law, 1e-3)."""
    contact = linear_contact(KN, 1.0, 0.5)

    def pair(overlap: float, tolerance: float):
        gap = 2.0 * R - overlap * R
        pos = [[0.05 - 0.5 * gap, 0.05, 0.05], [0.05 + 0.5 * gap, 0.05, 0.05]]
        return particle_scene(pos, R, contact=contact, overlap_tolerance=tolerance)

    refused_pair, _ = _refusal(lambda: pair(0.3, 0.05))
    refused_wall, _ = _refusal(
        lambda: particle_scene([[0.05, 0.05, 0.7 * R]], R, contact=contact, walls=["z-"])
    )
    error, scene = _refusal(lambda: pair(0.45, 0.5))
    energy_err = None
    energy_bound = None
    if scene is not None:
        e0 = observables(scene)["total_energy"]
        # Verlet's energy error on a linear spring is at most ~(omega dt)^2/4 of the energy
        energy_bound = (scene.state.clock.dt * math.sqrt(KN / (0.5 * MASS))) ** 2 / 4.0
        try:
            for _ in range(200):
                advance(scene, 10)
                check_stable(scene)
                if observables(scene)["contacts"] == 0:
                    break
        except NumericalError as exc:
            error = exc
        after = observables(scene)
        energy_err = abs(after["total_energy"] - e0) / e0 if after["contacts"] == 0 else None
    checks = [
        {
            "check": "pair overlap 0.3 R > tolerance 0.05: refused naming particles.overlap_tolerance",
            "passed": isinstance(refused_pair, CaseError) and "overlap_tolerance" in str(refused_pair),
            "detail": _first_line(str(refused_pair)),
        },
        {
            "check": "wall overlap 0.3 R > tolerance 0.05: refused naming the tolerance",
            "passed": isinstance(refused_wall, CaseError) and "overlap_tolerance" in str(refused_wall),
            "detail": _first_line(str(refused_wall)),
        },
        {
            "check": "overlap 0.45 R accepted at tolerance 0.5 separates, energy within (omega dt)^2/4",
            "passed": error is None and energy_err is not None and energy_err <= energy_bound,
            "detail": str(error) if error else f"energy error {energy_err}",
        },
    ]
    return {
        "action": "refused",
        "exit_code": getattr(refused_pair, "exit_code", 0),
        "theory": "overlap <= particles.overlap_tolerance x smaller radius (at most 0.5)",
        "theory_dt_s": None,
        "largest_stable_ratio": None,
        "detail": _first_line(str(refused_pair))
        + f"; 0.45 R at tolerance 0.5 released at dt = auto: energy error {energy_err:.3g}"
        if energy_err is not None
        else _first_line(str(refused_pair)),
        "checks": checks,
    }


_register(
    StabilityCase(
        "stability-huge-overlap",
        "initial overlaps beyond the tolerance (pair 0.3 R, wall 0.3 R); 0.45 R inside it",
        "refused",
        huge_overlap,
    )
)


# ------------------------------------------------------- failures during a run: the guard


def _run_dir_case(folder: Path, csv: str, **keys) -> Path:
    text = case_text(placement_file="placement.csv", **keys)
    text += textwrap.dedent(
        """
        [output.frames]
        every_steps = 50
        [output.checkpoints]
        every_steps = 50
        keep = 3
        """
    )
    (folder / "placement.csv").write_text(csv, encoding="utf-8")
    path = folder / "case.toml"
    path.write_text(text, encoding="utf-8")
    return path


def _guard_checks(exc, run_dir: Path, particle: int, first_bad_step: int, every: int) -> list[dict]:
    """The failure names step, time and particle, comes within `every` steps of the first bad
    state, and the newest checkpoint still verifies and holds a finite state."""
    from ..io.checkpoint import newest_valid_checkpoint

    message = str(exc) if exc is not None else ""
    match = re.search(r"at step (\d+) \(t = ([0-9.eE+-]+) s\): particle (\d+)", message)
    step = int(match.group(1)) if match else None
    ck = newest_valid_checkpoint(run_dir / "checkpoints")
    finite = ck is not None and all(
        np.all(np.isfinite(np.asarray(a))) for a in ck.arrays["particles"].values()
    )
    return [
        {
            "check": "NumericalError (exit 70)",
            "passed": isinstance(exc, NumericalError) and exc.exit_code == 70,
            "detail": type(exc).__name__ if exc else "no error: the run finished",
        },
        {
            "check": f"names step, time and particle {particle}",
            "passed": match is not None and int(match.group(3)) == particle,
            "detail": _first_line(message)[:160],
        },
        {
            "check": f"caught within {every} steps of the first bad state (step {first_bad_step})",
            "passed": step is not None and first_bad_step <= step <= first_bad_step + every,
            "detail": f"reported at step {step}",
        },
        {
            "check": "the newest checkpoint verifies and holds a finite state from before the failure",
            "passed": finite and ck.step < (step or 0),
            "detail": f"checkpoint at step {ck.step}" if ck else "no valid checkpoint",
        },
    ]


def escape(quick: bool) -> dict:
    """A particle leaving the box through an open face (no wall, not periodic) during `sphere
    run`: a NumericalError naming step, time and particle, the last checkpoint intact."""
    from .. import api

    speed = 1.0  # m/s towards x+ from 5 mm inside a 0.02 m box
    dt = 1.0e-5
    with tempfile.TemporaryDirectory(prefix="sphere-verify-") as tmp:
        folder = Path(tmp)
        pos = [[0.01, 0.01, 0.01], [0.005, 0.01, 0.01]]
        path = _run_dir_case(
            folder,
            particle_csv(pos, R, [[speed, 0.0, 0.0], [0.0, 0.0, 0.0]]),
            contact=linear_contact(KN, 0.5, 0.5),
            upper=(0.02, 0.02, 0.02),
            dt=dt,
            duration=0.05,
        )
        # it is outside once x > upper + R: after (0.02 + R - 0.01)/speed
        first_bad = math.floor((0.02 + R - 0.01) / speed / dt) + 1
        error = None
        try:
            api.run(path, folder / "run")
        except SphereError as exc:
            error = exc
        checks = _guard_checks(error, folder / "run", 0, first_bad, 100)
    return {
        "action": "reported" if isinstance(error, NumericalError) else "ran",
        "exit_code": getattr(error, "exit_code", 0),
        "theory": "guard every simulation.blowup_check_every = 100 steps",
        "theory_dt_s": None,
        "largest_stable_ratio": None,
        "detail": _first_line(str(error)) if error else "the run finished: the escape went unreported",
        "checks": checks,
    }


_register(
    StabilityCase(
        "stability-escape",
        "a particle leaves the box through an open face during a run",
        "reported",
        escape,
    )
)


class _PoisonedForces:
    """A stand-in for a kernel bug: the wrapped force module's forces, with particle `index`'s
    force set to NaN when the step `step` is computed."""

    def __init__(self, inner, step: int, index: int):
        self.inner, self.step, self.index = inner, step, index

    def forces(self, state, spring_dt=None):
        self.inner.forces(state, spring_dt)
        if state.clock.step + 1 == self.step:
            state.particles.force[self.index, :] = np.nan

    def __getattr__(self, name):
        return getattr(self.inner, name)


def nan_guard(quick: bool) -> dict:
    """A NaN appearing in the forces during a run (injected, as a kernel bug would) must be
    caught by the stability guard within blowup_check_every steps, reported with step, time and
    particle, and never reach a checkpoint."""
    from .. import api
    from ..config.load import load_case
    from ..io.rundir import RunDirectory
    from ..scene.builder import build_scene

    poison_step, index, every = 237, 3, 100
    rng = np.random.default_rng(1)
    pos = 0.01 + np.stack([np.arange(6) * 3.0 * R, np.zeros(6), np.zeros(6)], axis=1)
    vel = rng.normal(0.0, 0.05, (6, 3))
    with tempfile.TemporaryDirectory(prefix="sphere-verify-") as tmp:
        folder = Path(tmp)
        path = _run_dir_case(
            folder,
            particle_csv(pos, R, vel),
            contact=linear_contact(KN, 0.5, 0.5),
            upper=(0.04, 0.02, 0.02),
            walls=["x-", "x+", "y-", "y+", "z-", "z+"],
            gravity=(0.0, 0.0, -G),
            dt=1.0e-5,
            stability="contact",  # ten spheres thrown about: never a packing
            duration=0.01,
            blowup_check_every=every,
        )
        # what api.run does, with the contact module wrapped by the fault
        began = api._began()
        loaded = load_case(path)
        scene = build_scene(loaded)
        scene.contact = _PoisonedForces(scene.contact, poison_step, index)
        scene.order_modules()
        rundir = RunDirectory(folder / "run")
        rundir.prepare_new(False, loaded.text)
        log = rundir.logger()
        output = api.start_output(scene, rundir, loaded, log)
        error = None
        try:
            api._drive(scene, rundir, output, log, None, False, False, began)
        except SphereError as exc:
            error = exc
        finally:
            rundir.unlock()
        checks = _guard_checks(error, rundir.path, index, poison_step, every)
        status = rundir.status_path.read_text() if rundir.status_path.exists() else ""
        checks.append(
            {"check": "status.json says failed", "passed": '"failed"' in status, "detail": status[:80]}
        )
    return {
        "action": "reported" if isinstance(error, NumericalError) else "ran",
        "exit_code": getattr(error, "exit_code", 0),
        "theory": f"guard every simulation.blowup_check_every = {every} steps",
        "theory_dt_s": None,
        "largest_stable_ratio": None,
        "detail": _first_line(str(error)) if error else "the NaN went unreported",
        "checks": checks,
    }


_register(
    StabilityCase(
        "stability-nan-guard",
        "a NaN appears in the forces during a run (injected fault)",
        "reported",
        nan_guard,
    )
)


def _first_line(text: str) -> str:
    """The first line of a message, without the temporary folders the cases run in."""
    line = text.strip().splitlines()[0] if text.strip() else ""
    return re.sub(r"\S*sphere-verify-[^/\s]+/", "", line)


def run_stability_case(case: StabilityCase, quick: bool = False) -> dict:
    """Run one stability case; returns its JSON record with a verdict."""
    started = time.perf_counter()
    try:
        result = case.run(quick)
    except Exception as exc:  # a crash is a failure of the case, reported as such
        result = {
            "action": "crashed",
            "detail": f"{type(exc).__name__}: {exc}",
            "checks": [{"check": "runs", "passed": False, "detail": f"{type(exc).__name__}: {exc}"}],
        }
    record = {
        "name": case.name,
        "title": case.title,
        "expected": case.expected,
        "theory": result.get("theory"),
        "theory_dt_s": result.get("theory_dt_s"),
        "largest_stable_ratio": result.get("largest_stable_ratio"),
        "action": result["action"],
        "exit_code": result.get("exit_code"),
        "detail": result.get("detail", ""),
        "checks": result["checks"],
        "seconds": time.perf_counter() - started,
    }
    action_ok = record["action"] == case.expected
    record["checks"].insert(
        0, {"check": f"the program {case.expected}", "passed": action_ok, "detail": record["action"]}
    )
    record["passed"] = all(c["passed"] for c in record["checks"])
    return record


from . import fluid_stability  # noqa: E402, F401  (the fluids' cases register themselves into STABILITY)
