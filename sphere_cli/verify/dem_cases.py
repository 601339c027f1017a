"""DEM verification cases with the linear spring-dashpot contact (verification
groups A1 and A4). Resolution: time steps per contact duration (the clamped closed-form t_c
of physics/restitution.py), for free fall: steps per fall.

Every scene is built through the case-file path (scenes.py). Where the dashpot force jumps
from 0 to c v at the touch, a fixed step places that instant only to +-dt/2, an O(dt) impulse
error whose sign depends on where in a step the touch falls (the touch phase). Cases that
measure the scheme's systematic order place the touch at mid-step, which cancels that term;
the touch-phase case measures the worst phase, which is what a real packing sees.
"""

from __future__ import annotations

import math

import numpy as np

from ..config.schema import Simulation
from ..physics.contact import verlet_limit
from ..physics.observe.energy import observables
from ..physics.restitution import linear_contact_time, linear_damping_ratio
from .analytic import DampedImpact, bounce_apexes
from .registry import Outcome, Stepper, Tolerance, VerificationCase, register
from .scenes import linear_contact, particle_scene, sphere_mass

R = 1.0e-3  # m
DENSITY = 2500.0  # kg/m^3
MASS = sphere_mass(R, DENSITY)
KN = 1.0e3  # N/m
G = 9.81  # m/s^2
SPEED = 0.1  # m/s, each sphere of a pair, or the sphere on a wall
LEAD_STEPS = 3  # whole steps of free flight before the touch
WINDOW = 1.5  # the trajectory is compared up to t_touch + WINDOW t_c

A1_SOURCE = "verification group A1: 0.5 % on e and t_c with >= 50 steps per contact"
A4_SOURCE = "verification group A4: 1 %"


# ------------------------------------------------------------------------ A1: one impact


def linear_impact(spc: float, e: float, on_wall: bool, phase: float = 0.5, energy: bool = False) -> Outcome:
    """One head-on linear impact at `spc` steps per (clamped) contact duration, the touch at
    `phase` of a step. Errors: restitution and contact time (relative), the overlap history
    delta(t) against the closed form (L2 = RMS over the steps, L-inf; relative to the peak
    overlap), with energy=True the total energy (after the impact and L-inf over the run)."""
    m_eff = MASS if on_wall else 0.5 * MASS
    zeta = linear_damping_ratio(e)
    t_ref = linear_contact_time(KN, m_eff, zeta, clamped=True)
    dt = t_ref / spc
    v_in = SPEED if on_wall else 2.0 * SPEED  # normal approach speed
    t_touch = (LEAD_STEPS + phase) * dt
    gap = v_in * t_touch
    contact = linear_contact(KN, e, 0.5)
    if on_wall:
        scene = particle_scene(
            [[0.05, 0.05, R + gap]], R, [[0.0, 0.0, -SPEED]], contact=contact, walls=["z-"], dt=dt
        )
    else:
        x0 = 0.05
        pos = [[x0 - R - 0.5 * gap, 0.05, 0.05], [x0 + R + 0.5 * gap, 0.05, 0.05]]
        scene = particle_scene(pos, R, [[SPEED, 0.0, 0.0], [-SPEED, 0.0, 0.0]], contact=contact, dt=dt)
    p = scene.state.particles
    cn = 2.0 * zeta * math.sqrt(KN * m_eff)

    def overlap() -> float:
        return R - p.pos[0, 2] if on_wall else 2.0 * R - (p.pos[1, 0] - p.pos[0, 0])

    def approach() -> float:
        return -p.vel[0, 2] if on_wall else p.vel[0, 0] - p.vel[1, 0]

    momentum0 = (p.mass[:, None] * p.vel).sum(axis=0)
    scale = float((p.mass[:, None] * np.abs(p.vel)).sum())
    e0 = observables(scene)["total_energy"] if energy else 0.0
    energy_dev = 0.0
    steps = math.ceil((t_touch + WINDOW * t_ref) / dt)
    stepper = Stepper(scene)
    deltas = np.empty(steps)
    touching, t_end = False, None
    for n in range(steps):
        before = KN * overlap() + cn * approach()
        stepper.advance(1)
        deltas[n] = overlap()
        if energy:
            energy_dev = max(energy_dev, abs(observables(scene)["total_energy"] - e0))
        if np.any(p.force[0] != 0.0):
            touching = True
        elif touching and t_end is None:
            # the clamped force reached zero within the last step: interpolate the unclamped one
            after = KN * overlap() + cn * approach()
            t_end = (n * dt) + dt * before / (before - after)
    if t_end is None:
        raise RuntimeError("the contact did not end within the window")
    reference = DampedImpact(KN, m_eff, zeta, v_in)
    times = (np.arange(steps) + 1) * dt - t_touch
    err = (deltas - reference.separating_overlap(times)) / reference.peak_overlap
    e_real = -approach() / v_in
    t_contact = t_end - t_touch
    out = Outcome(
        dt=dt,
        steps=steps,
        particles=p.count,
        errors={
            "e": abs(e_real - e) / e,
            "t_c": abs(t_contact - t_ref) / t_ref,
            "L2": float(np.sqrt(np.mean(err**2))),
            "Linf": float(np.abs(err).max()),
        },
        values={"e": e_real, "t_c": t_contact, "t_c_ref": t_ref},
        step_seconds=stepper.seconds,
    )
    if not on_wall:
        momentum = (p.mass[:, None] * p.vel).sum(axis=0)
        out.drift["momentum"] = float(np.abs(momentum - momentum0).max() / scale)
    if energy:
        out.errors["energy"] = abs(observables(scene)["total_energy"] - e0) / e0
        out.errors["energy_Linf"] = energy_dev / e0
        out.drift["energy"] = out.errors["energy"]
    return out


IMPACT_LABELS = {
    "e": "restitution |e - e_ref|/e_ref",
    "t_c": "contact time |t_c - t_ref|/t_ref",
    "L2": "overlap history, RMS error / peak overlap",
    "Linf": "overlap history, max error / peak overlap",
}
A1_TOLERANCES = (
    Tolerance("e", 5e-3, 50, source=A1_SOURCE),
    Tolerance("t_c", 5e-3, 50, source=A1_SOURCE),
)
MID_STEP_NOTE = (
    "velocity Verlet with the dashpot at the predicted velocity v_n + dt a_n is second order; "
    "the touch is placed at mid-step, which cancels the O(dt) error of the dashpot switching on "
    "between steps (see the touch-phase case)"
)

register(
    VerificationCase(
        name="a1-linear-pair",
        title="A1 linear spring-dashpot, two equal spheres head-on (e = 0.5)",
        model="linear",
        reference=(
            "clamped linear spring-dashpot: e as requested, t_c = 2 acos(zeta)/(omega0 sqrt(1 - zeta^2)), "
            "delta(t) = (v/omega) exp(-zeta omega0 t) sin(omega t) (Schwager & Poeschel 2007, Granular "
            "Matter 9:465; verification group A1)"
        ),
        description=(
            f"R = {R} m, rho = {DENSITY} kg/m^3, k_n = {KN} N/m, e = 0.5, approach speed {2 * SPEED} m/s, "
            "m* = m/2, no gravity; run to 1.5 t_c after the touch"
        ),
        run=lambda spc: linear_impact(spc, 0.5, on_wall=False),
        ladder=(12.5, 25, 50, 100, 200, 400, 800),
        quick_ladder=(25, 50, 100),
        error_labels=IMPACT_LABELS,
        order_metrics=("e", "t_c", "L2"),
        formal_order=2.0,
        min_order=1.8,
        order_note=MID_STEP_NOTE,
        tolerances=A1_TOLERANCES,
        drift_bounds={"momentum": 1e-14},
    )
)

register(
    VerificationCase(
        name="a1-linear-wall",
        title="A1 linear spring-dashpot, sphere on a fixed wall (e = 0.2)",
        model="linear",
        reference="as a1-linear-pair with m* = m (a wall is a body of infinite mass)",
        description=(
            f"R = {R} m, rho = {DENSITY} kg/m^3, k_n = {KN} N/m, e = 0.2 (strong damping, zeta = "
            f"{linear_damping_ratio(0.2):.3f}), impact speed {SPEED} m/s, no gravity"
        ),
        run=lambda spc: linear_impact(spc, 0.2, on_wall=True),
        ladder=(12.5, 25, 50, 100, 200, 400, 800),
        quick_ladder=(25, 50, 100),
        error_labels=IMPACT_LABELS,
        order_metrics=("e", "t_c", "L2"),
        formal_order=2.0,
        min_order=1.8,
        order_note=MID_STEP_NOTE,
        tolerances=A1_TOLERANCES,
    )
)

PHASES = tuple(k / 8.0 for k in range(8))


def linear_impact_any_phase(spc: float, e: float) -> Outcome:
    """A1 at every touch phase k/8 of a step: the worst error over the phases."""
    runs = [linear_impact(spc, e, on_wall=False, phase=phase) for phase in PHASES]
    worst = {name: max(r.errors[name] for r in runs) for name in runs[0].errors}
    values = {
        "e_min": min(r.values["e"] for r in runs),
        "e_max": max(r.values["e"] for r in runs),
        "t_c_ref": runs[0].values["t_c_ref"],
    }
    return Outcome(
        dt=runs[0].dt,
        steps=sum(r.steps for r in runs),
        particles=runs[0].particles,
        errors=worst,
        values=values,
        drift={"momentum": max(r.drift["momentum"] for r in runs)},
        step_seconds=sum(r.step_seconds for r in runs),
    )


DEFAULT_SAFETY = Simulation.model_fields["dt_safety"].default


def steps_per_contact_at_auto(e: float, m_eff: float, safety: float = DEFAULT_SAFETY) -> float:
    """t_c/dt of dt = "auto" for the linear contact (k_n, k_t = 2/7 k_n) of two spheres at this e:
    the limit of the one contact (physics/contact.verlet_limit) times the default dt_safety (their
    bound, a pair's own, is no tighter)."""
    zeta = linear_damping_ratio(e)
    limit = verlet_limit(KN, 2.0 / 7.0 * KN, zeta, m_eff)
    return linear_contact_time(KN, m_eff, zeta, clamped=True) / (safety * limit)


AUTO_SPC = round(steps_per_contact_at_auto(0.5, 0.5 * MASS), 1)

register(
    VerificationCase(
        name="a1-touch-phase",
        title="A1 at an arbitrary touch phase: worst restitution over 8 phases (e = 0.5)",
        model="linear",
        reference="as a1-linear-pair",
        description=(
            "the pair impact of a1-linear-pair run 8 times, the touch at 0, 1/8, ..., 7/8 of a step; "
            "the worst error over the phases is reported (steps are the sum over the 8 runs); "
            f'{AUTO_SPC:g} steps per contact is what dt = "auto" ({DEFAULT_SAFETY:g} x the limit of the '
            "contact) gives here"
        ),
        run=lambda spc: linear_impact_any_phase(spc, 0.5),
        ladder=(AUTO_SPC, 25, 50, 100, 200, 400, 800),
        quick_ladder=(50, 100, 200),
        error_labels={k: "worst phase: " + v for k, v in IMPACT_LABELS.items()},
        order_metrics=("e", "L2"),
        formal_order=1.0,
        min_order=0.9,
        order_note=(
            "the dashpot force jumps from 0 to c v at the touch, which a fixed step resolves only to "
            "+-dt/2: an impulse error of order c v dt, first order in dt (t_c, set by the smooth end "
            "of the contact, stays second order)"
        ),
        tolerances=(
            Tolerance(
                "e",
                5e-3,
                200,
                source=(
                    "A1's 0.5 %, which at the worst touch phase this scheme reaches only from 200 "
                    "steps per contact at e = 0.5 (at 50: 1.5 %)"
                ),
            ),
            Tolerance("t_c", 5e-3, 50, source=A1_SOURCE),
        ),
        drift_bounds={"momentum": 1e-14},
    )
)


register(
    VerificationCase(
        name="a4-elastic-energy-linear",
        title="A4 elastic collision, linear spring (e = 1): energy error",
        model="linear",
        reference=(
            "an elastic collision conserves energy; velocity Verlet is symplectic, its energy error "
            "is O(dt^2) (Hairer, Lubich & Wanner, Geometric Numerical Integration, 2006, IX.8); "
            "verification group A4: order >= 1.8"
        ),
        description=(
            f"two equal spheres head-on, R = {R} m, k_n = {KN} N/m, e = 1, approach speed "
            f"{2 * SPEED} m/s; energy = kinetic + elastic, measured every step"
        ),
        run=lambda spc: linear_impact(spc, 1.0, on_wall=False, energy=True),
        ladder=(12.5, 25, 50, 100, 200, 400, 800),
        quick_ladder=(25, 50, 100),
        error_labels={
            **IMPACT_LABELS,
            "energy": "|E_after - E_before|/E_before",
            "energy_Linf": "max over the run |E(t) - E_0|/E_0",
        },
        order_metrics=("energy", "energy_Linf", "L2"),
        formal_order=2.0,
        min_order=1.8,
        order_note=(
            "energy error during the contact O(dt^2); after the contact the linear spring's error "
            "cancels further (observed ~4 with the touch at mid-step)"
        ),
        tolerances=(
            Tolerance("e", 1e-3, 50, source="e = 1 must rebound at 1 +- 1e-3 (verification group A3)"),
            Tolerance("energy", 2e-3, 50, source="e = 1 +- 1e-3 (A3) means energy within 2e-3"),
        ),
        drift_bounds={"momentum": 1e-14},
    )
)


# ------------------------------------------------------------------------ A4: free fall


FALL_TIME = 0.02  # s


def free_fall(steps: float) -> Outcome:
    """Two spheres in free flight under gravity for FALL_TIME in `steps` steps; every step is
    compared with z0 + w0 t - g t^2/2 and v0 - g t."""
    steps = int(steps)
    dt = FALL_TIME / steps
    pos0 = np.array([[0.03, 0.05, 0.09], [0.07, 0.05, 0.08]])
    vel0 = np.array([[0.01, 0.0, 0.0], [0.0, -0.02, 0.2]])
    g = np.array([0.0, 0.0, -G])
    # nothing touches: an undamped contact law, whose stability limit 2/omega admits every dt here
    scene = particle_scene(pos0, R, vel0, contact=linear_contact(KN, 1.0, 0.5), gravity=tuple(g), dt=dt)
    p = scene.state.particles
    stepper = Stepper(scene)
    pos_err = vel_err = 0.0
    for n in range(1, steps + 1):
        stepper.advance(1)
        t = n * dt
        pos_err = max(pos_err, float(np.abs(p.pos - (pos0 + vel0 * t + 0.5 * g * t * t)).max()))
        vel_err = max(vel_err, float(np.abs(p.vel - (vel0 + g * t)).max()))
    return Outcome(
        dt=dt,
        steps=steps,
        particles=p.count,
        errors={"position": pos_err / 0.1, "velocity": vel_err / (G * FALL_TIME)},
        values={"t_end": scene.state.clock.time},
        step_seconds=stepper.seconds,
    )


register(
    VerificationCase(
        name="a4-free-fall",
        title="A4 free fall: exact to round-off",
        model="linear",
        reference="z = z0 + w0 t - g t^2/2, v = v0 - g t (verification group A4: to round-off)",
        description=(
            f"two spheres in free flight for {FALL_TIME} s under g = {G} m/s^2 (one thrown up); every "
            "step compared; position error relative to the box (0.1 m), velocity error to g T"
        ),
        run=free_fall,
        ladder=(250, 500, 1000, 2000, 4000),
        quick_ladder=(250, 1000),
        resolution="steps per fall",
        error_labels={
            "position": "max over steps |x - x_exact| / 0.1 m",
            "velocity": "max over steps |v - v_exact| / (g T)",
        },
        formal_order=None,
        order_note=(
            "exact: velocity Verlet is the Taylor series of a constant-force motion, so only "
            "rounding remains (no order to fit)"
        ),
        tolerances=(
            Tolerance("position", ulps_per_step=2.0, source="A4: round-off, <= 2 ulps per step"),
            Tolerance("velocity", ulps_per_step=2.0, source="A4: round-off, <= 2 ulps per step"),
        ),
        roundoff_floor=1.0,
    )
)


# ------------------------------------------------------------------------ A4: bouncing ball


BOUNCE_KN = 1.0e4  # N/m: a stiff wall, so gravity during the contact matters little
BOUNCE_E = 0.9
BOUNCE_H0 = 1.0e-3  # m, drop height of the sphere's lowest point
BOUNCES = 3


def bouncing_ball(spc: float) -> Outcome:
    """A sphere dropped from BOUNCE_H0 onto a wall; apex heights of the first BOUNCES bounces.
    The apex is located from the last rising step, z + v^2/(2 g) (exact in free flight)."""
    t_c = linear_contact_time(BOUNCE_KN, MASS, linear_damping_ratio(BOUNCE_E), clamped=True)
    dt = t_c / spc
    contact = linear_contact(BOUNCE_KN, BOUNCE_E, 0.5)
    scene = particle_scene(
        [[0.05, 0.05, R + BOUNCE_H0]], R, None, contact=contact, gravity=(0.0, 0.0, -G), walls=["z-"], dt=dt
    )
    p = scene.state.particles
    stepper = Stepper(scene)
    apex: list[float] = []
    rising = False
    z_prev, w_prev = float(p.pos[0, 2]), 0.0
    while len(apex) < BOUNCES:
        stepper.advance(1)
        w = float(p.vel[0, 2])
        if w > 0.0:
            rising = True
        if rising and w <= 0.0:
            apex.append(z_prev + w_prev * w_prev / (2.0 * G) - R)
            rising = False
        z_prev, w_prev = float(p.pos[0, 2]), w
        if stepper.steps > 100 * spc * 1000:
            raise RuntimeError("the ball did not bounce")
    apex_arr = np.array(apex)
    model = bounce_apexes(BOUNCE_H0, BOUNCE_KN, MASS, linear_damping_ratio(BOUNCE_E), G, BOUNCES)
    ideal = BOUNCE_H0 * BOUNCE_E ** (2 * np.arange(1, BOUNCES + 1))
    rel_model = (apex_arr - model) / model
    rel_ideal = (apex_arr - ideal) / ideal
    return Outcome(
        dt=dt,
        steps=stepper.steps,
        particles=1,
        errors={
            "apex": float(np.abs(rel_ideal).max()),
            "apex_model": float(np.abs(rel_model).max()),
            "apex_model_L2": float(np.sqrt(np.mean(rel_model**2))),
        },
        values={f"h{n + 1}": float(h) for n, h in enumerate(apex_arr)},
        step_seconds=stepper.seconds,
    )


register(
    VerificationCase(
        name="a4-bouncing-ball",
        title=f"A4 bouncing ball: apex heights h_n = e^(2n) h0 (e = {BOUNCE_E})",
        model="linear",
        reference=(
            "h_n = e^{2n} h0 (verification group A4, 1 %); the order is measured against the exact "
            "solution of the clamped linear model with gravity during the contact (analytic.py), "
            "which differs from e^{2n} h0 by -0.07 %, -0.14 %, -0.22 % for n = 1, 2, 3"
        ),
        description=(
            f"R = {R} m, k_n = {BOUNCE_KN} N/m, e = {BOUNCE_E}, dropped from h0 = {BOUNCE_H0} m "
            f"(lowest point), g = {G} m/s^2; the first {BOUNCES} apexes"
        ),
        run=bouncing_ball,
        ladder=(25, 50, 100, 200, 400, 800),
        quick_ladder=(50, 100),
        error_labels={
            "apex": "max_n |h_n - e^{2n} h0| / (e^{2n} h0)",
            "apex_model": "max_n |h_n - h_n(model)| / h_n(model)",
            "apex_model_L2": "RMS over n of the same",
        },
        order_metrics=("apex_model",),
        formal_order=1.0,
        min_order=None,
        order_note=(
            "each bounce touches at an arbitrary phase of a step, so the O(dt) error of the dashpot "
            "switching on has an erratic sign from bounce to bounce: first order on average, not "
            "monotone, hence reported and not enforced"
        ),
        tolerances=(
            Tolerance(
                "apex",
                1e-2,
                100,
                source=(
                    "A4 1 %, from 100 steps per contact: worst touch phase <= 0.12 % per bounce on e "
                    "(a1-touch-phase at e = 0.9), so <= 0.7 % on h_3, plus 0.22 % from gravity"
                ),
            ),
        ),
    )
)


# ------------------------------------------------------------------- A4: sliding -> rolling


SLIDE_MU = 0.3
SLIDE_V0 = 0.3  # m/s


def sliding_to_rolling(spc: float) -> Outcome:
    """A sphere launched sliding at v0 without spin on a floor (starting at its static overlap):
    time t* at which the slip first vanishes (interpolated between steps) and the speed 0.5 t*
    later; x(t) compared with the rigid-body solution over 1.5 t*."""
    e = 0.5
    t_c = linear_contact_time(KN, MASS, linear_damping_ratio(e), clamped=True)
    dt = t_c / spc
    z0 = R - MASS * G / KN
    x0 = 0.01
    scene = particle_scene(
        [[x0, 0.05, z0]],
        R,
        [[SLIDE_V0, 0.0, 0.0]],
        contact=linear_contact(KN, e, SLIDE_MU),
        gravity=(0.0, 0.0, -G),
        walls=["z-"],
        dt=dt,
        upper=(0.2, 0.1, 0.1),
    )
    p = scene.state.particles
    stepper = Stepper(scene)
    t_star = 2.0 * SLIDE_V0 / (7.0 * SLIDE_MU * G)
    x_star = x0 + SLIDE_V0 * t_star - 0.5 * SLIDE_MU * G * t_star**2
    v_final = 5.0 * SLIDE_V0 / 7.0
    steps = math.ceil(1.5 * t_star / dt)
    measured = None
    slip_prev = SLIDE_V0
    x_err = 0.0
    for n in range(1, steps + 1):
        stepper.advance(1)
        t = n * dt
        slip = p.vel[0, 0] - R * p.angvel[0, 1]  # velocity of the contact point
        if measured is None and slip <= 0.0 < slip_prev:
            measured = t - dt * slip / (slip - slip_prev)
        slip_prev = slip
        x_ref = (
            x0 + SLIDE_V0 * t - 0.5 * SLIDE_MU * G * t * t if t < t_star else x_star + v_final * (t - t_star)
        )
        x_err = max(x_err, abs(float(p.pos[0, 0]) - x_ref))
    if measured is None:
        raise RuntimeError("the sphere never stopped slipping")
    return Outcome(
        dt=dt,
        steps=steps,
        particles=1,
        errors={
            "t_star": abs(measured - t_star) / t_star,
            "v_final": abs(float(p.vel[0, 0]) - v_final) / v_final,
            "slip": abs(float(slip)) / SLIDE_V0,
            "x_Linf": x_err / R,
        },
        values={"t_star": measured, "t_star_ref": t_star, "v_final": float(p.vel[0, 0])},
        step_seconds=stepper.seconds,
    )


register(
    VerificationCase(
        name="a4-sliding-rolling",
        title="A4 sliding sphere starts rolling: t* = 2 v0/(7 mu g), final speed 5 v0/7",
        model="linear",
        reference=(
            "t* = 2 v0/(7 mu g), v = 5 v0/7 (rigid sphere, Coulomb friction; verification group A4, 1 %)"
        ),
        description=(
            f"R = {R} m, k_n = {KN} N/m, e = 0.5, mu = {SLIDE_MU}, v0 = {SLIDE_V0} m/s, no spin, on a "
            "floor under gravity, starting at the static overlap"
        ),
        run=sliding_to_rolling,
        ladder=(12.5, 25, 50, 100, 200, 400),
        quick_ladder=(25, 50),
        error_labels={
            "t_star": "|t* - 2 v0/(7 mu g)| / t*",
            "v_final": "|v - 5 v0/7| / (5 v0/7) at 1.5 t*",
            "slip": "|slip velocity| / v0 at 1.5 t*",
            "x_Linf": "max over steps |x - x_rigid| / R",
        },
        formal_order=None,
        order_note=(
            "no truncation error to converge: while sliding the friction is constant (mu m g), "
            "which velocity Verlet integrates exactly, and 5 v0/7 follows from angular momentum about "
            "the contact point (round-off); what is left of the t* error is the location of the "
            "slip's zero crossing between two steps, and x(t) departs from the rigid-body path by "
            "the elastic compliance of the contact, independent of dt"
        ),
        tolerances=(
            Tolerance("t_star", 1e-2, source=A4_SOURCE),
            Tolerance("v_final", 1e-2, source=A4_SOURCE),
            Tolerance("slip", 1e-6, source="rolls without slip after t*"),
        ),
        roundoff_floor=1e-11,
    )
)


# ----------------------------------------------------------------------- A4: oblique impact


OBLIQUE_MU = 0.3
OBLIQUE_VN = 0.1  # m/s
OBLIQUE_VT = 1.0  # m/s: gross sliding needs v_t > (7/2) mu (1 + e) v_n


def oblique_impact(spc: float, e: float = 0.5) -> Outcome:
    """A sphere hits a wall at v_n with tangential speed v_t (no spin), sliding throughout; the
    changes of tangential velocity and spin over the impact (touch at mid-step)."""
    t_c = linear_contact_time(KN, MASS, linear_damping_ratio(e), clamped=True)
    dt = t_c / spc
    gap = OBLIQUE_VN * (LEAD_STEPS + 0.5) * dt
    scene = particle_scene(
        [[0.05, 0.05, R + gap]],
        R,
        [[OBLIQUE_VT, 0.0, -OBLIQUE_VN]],
        contact=linear_contact(KN, e, OBLIQUE_MU),
        walls=["z-"],
        dt=dt,
    )
    p = scene.state.particles
    stepper = Stepper(scene)
    touched = False
    while True:
        stepper.advance(1)
        if np.any(p.force[0] != 0.0):
            touched = True
        elif touched:
            break
        if stepper.steps > 20 * spc:
            raise RuntimeError("the impact did not end")
    e_real = float(p.vel[0, 2]) / OBLIQUE_VN
    dv_t = float(p.vel[0, 0]) - OBLIQUE_VT
    spin = float(p.angvel[0, 1])
    dv_ref = -OBLIQUE_MU * (1.0 + e) * OBLIQUE_VN
    spin_ref = 2.5 * OBLIQUE_MU * (1.0 + e) * OBLIQUE_VN / R
    return Outcome(
        dt=dt,
        steps=stepper.steps,
        particles=1,
        errors={
            "dv_t": abs(dv_t - dv_ref) / abs(dv_ref),
            "spin": abs(spin - spin_ref) / spin_ref,
            "impulse_ratio": abs(dv_t / (-OBLIQUE_MU * (1.0 + e_real) * OBLIQUE_VN) - 1.0),
        },
        values={"dv_t": dv_t, "spin": spin, "e": e_real, "slip_after": float(p.vel[0, 0]) - R * spin},
        step_seconds=stepper.seconds,
    )


register(
    VerificationCase(
        name="a4-oblique-impact",
        title="A4 oblique impact in gross sliding (e = 0.5)",
        model="linear",
        reference=(
            "dv_t = -mu (1+e) v_n, d omega = (5/2) mu (1+e) v_n/R (rigid sphere, Coulomb friction "
            "throughout; verification group A4, 1 %)"
        ),
        description=(
            f"R = {R} m, k_n = {KN} N/m, e = 0.5, mu = {OBLIQUE_MU}, v_n = {OBLIQUE_VN} m/s, "
            f"v_t = {OBLIQUE_VT} m/s, no gravity, touch at mid-step"
        ),
        run=oblique_impact,
        ladder=(12.5, 25, 50, 100, 200, 400),
        quick_ladder=(25, 50, 100),
        error_labels={
            "dv_t": "|dv_t + mu (1+e) v_n| / (mu (1+e) v_n)",
            "spin": "|omega - (5/2) mu (1+e) v_n/R| / same",
            "impulse_ratio": "tangential/normal impulse vs mu (with the realised e): round-off",
        },
        order_metrics=("dv_t", "spin"),
        formal_order=2.0,
        min_order=1.8,
        order_note="the error is that of the realised e (a1-linear-pair), second order at mid-step touch",
        tolerances=(
            Tolerance("dv_t", 1e-2, source=A4_SOURCE),
            Tolerance("spin", 1e-2, source=A4_SOURCE),
            Tolerance(
                "impulse_ratio",
                1e-12,
                source="Coulomb cap active throughout: F_t = mu F_n at every step, to round-off",
            ),
        ),
    )
)
