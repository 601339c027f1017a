"""DEM verification cases with the Hertz-Mindlin contact (verification group A2, A3 and
the Hertz energy order of A4). Resolution: time steps per contact duration.

A2: F = (4/3) E* sqrt(R*) delta^{3/2}; delta_max = (15 m* v^2/(16 E* sqrt(R*)))^{2/5},
F_max = (4/3) E* sqrt(R*) delta_max^{3/2}, t_c = 2.9433 delta_max/v (Hertz 1882).
A3: Chung & Ooi (2011), Granular Matter 13:643, tests 1-3, gravity off; published values to
four digits, tolerance 1 % with >= 100 steps per contact, e = 1 rebounding at 1 +- 1e-3.
"""

from __future__ import annotations

import math

import numpy as np

from ..physics.observe.energy import observables
from ..physics.restitution import hertz_contact_time, hertz_damping_coefficient, hertz_stiffness
from .analytic import HertzElasticImpact
from .registry import Outcome, Stepper, Tolerance, VerificationCase, register
from .scenes import particle_scene, sphere_mass

LEAD_STEPS = 3
WINDOW = 1.5
A3_SOURCE = "verification group A3 (Chung & Ooi 2011): 1 % with >= 100 steps per contact"


def hertz_contact(youngs: float, poisson: float, e: float, mu: float = 0.5) -> dict:
    """The [contact] table of the Hertz-Mindlin law with one material."""
    return {
        "model": "hertz-mindlin",
        "youngs_modulus": float(youngs),
        "poisson_ratio": float(poisson),
        "restitution": float(e),
        "friction": float(mu),
    }


def _effective(youngs: float, poisson: float, radius: float, density: float, on_wall: bool):
    """(E*, R*, m*) of two equal spheres or of a sphere on a rigid wall."""
    mass = sphere_mass(radius, density)
    inv_e = (1.0 - poisson**2) / youngs
    if on_wall:
        return 1.0 / inv_e, radius, mass
    return 1.0 / (2.0 * inv_e), 0.5 * radius, 0.5 * mass


def hertz_impact(
    spc: float,
    youngs: float,
    poisson: float,
    density: float,
    radius: float,
    speed: float,
    on_wall: bool,
    e: float = 1.0,
    energy: bool = False,
) -> tuple[Outcome, dict]:
    """One head-on Hertz impact (two equal spheres at +-speed, or a sphere at speed on a rigid
    wall), touch at mid-step, `spc` steps per contact. Returns the outcome (errors against the
    closed forms) and the measured values (delta_max, F_max, t_c, e)."""
    e_star, r_star, m_eff = _effective(youngs, poisson, radius, density, on_wall)
    k_h = hertz_stiffness(e_star, r_star)
    v_in = speed if on_wall else 2.0 * speed
    elastic = HertzElasticImpact(k_h, m_eff, v_in)
    t_ref = elastic.t_end if e == 1.0 else hertz_contact_time(m_eff, k_h, v_in, hertz_damping_coefficient(e))
    dt = t_ref / spc
    t_touch = (LEAD_STEPS + 0.5) * dt
    gap = v_in * t_touch
    contact = hertz_contact(youngs, poisson, e)
    box = 8.0 * radius
    centre = 0.5 * box
    # the spheres start apart: overlap_tolerance = 0 says so, which leaves the builder's dt limit
    # to the Rayleigh time rather than the tangent stiffness at a 5 % initial overlap, so that
    # the coarse rungs (25 steps per contact) are accepted for the damped contacts of test 3
    common = {
        "contact": contact,
        "density": density,
        "dt": dt,
        "upper": (box, box, box),
        "overlap_tolerance": 0.0,
    }
    if on_wall:
        scene = particle_scene(
            [[centre, centre, radius + gap]], radius, [[0.0, 0.0, -speed]], walls=["z-"], **common
        )
    else:
        pos = [[centre - radius - 0.5 * gap, centre, centre], [centre + radius + 0.5 * gap, centre, centre]]
        scene = particle_scene(pos, radius, [[speed, 0.0, 0.0], [-speed, 0.0, 0.0]], **common)
    p = scene.state.particles

    def overlap() -> float:
        return radius - p.pos[0, 2] if on_wall else 2.0 * radius - (p.pos[1, 0] - p.pos[0, 0])

    def approach() -> float:
        return -p.vel[0, 2] if on_wall else p.vel[0, 0] - p.vel[1, 0]

    damping = hertz_damping_coefficient(e) * math.sqrt(m_eff * k_h)

    def unclamped() -> float:
        """k_h delta^{3/2} + c_h sqrt(m* k_h) delta^{1/4} delta' (the overlap itself once apart)."""
        d = overlap()
        if d <= 0.0:
            return d
        return k_h * d**1.5 + damping * d**0.25 * approach()

    e0 = observables(scene)["total_energy"] if energy else 0.0
    energy_dev = 0.0
    steps = math.ceil((t_touch + WINDOW * t_ref) / dt)
    stepper = Stepper(scene)
    deltas = np.empty(steps)
    force_max = 0.0
    t_end = None
    touching = False
    for n in range(steps):
        before, before_delta = unclamped(), overlap()
        stepper.advance(1)
        deltas[n] = overlap()
        force_max = max(force_max, float(np.abs(p.force[0]).max()))
        if energy:
            energy_dev = max(energy_dev, abs(observables(scene)["total_energy"] - e0))
        if np.any(p.force[0] != 0.0):
            touching = True
        elif touching and t_end is None:
            # the clamped force vanished within the last step: linear interpolation of the
            # unclamped force (elastic: of the overlap, which closes there) is second order
            after = unclamped()
            if e == 1.0 or deltas[n] <= 0.0:
                before, after = before_delta, deltas[n]
            t_end = n * dt + dt * before / (before - after)
    if t_end is None:
        raise RuntimeError("the contact did not end within the window")
    measured = {
        "delta_max": float(deltas.max()),
        "F_max": force_max,
        "t_c": t_end - t_touch,
        "e": -approach() / v_in,
    }
    errors = {
        "delta_max": abs(measured["delta_max"] - elastic.delta_max) / elastic.delta_max,
        "F_max": abs(measured["F_max"] - elastic.force_max) / elastic.force_max,
        "t_c": abs(measured["t_c"] - t_ref) / t_ref,
    }
    if e == 1.0:
        times = (np.arange(steps) + 1) * dt - t_touch
        err = (deltas - elastic.separating_overlap(times)) / elastic.delta_max
        errors["L2"] = float(np.sqrt(np.mean(err**2)))
        errors["Linf"] = float(np.abs(err).max())
        errors["e"] = abs(measured["e"] - 1.0)
    else:
        del errors["delta_max"], errors["F_max"]  # the closed forms are for the elastic contact
        errors["e"] = abs(measured["e"] - e)
    if energy:
        errors["energy"] = abs(observables(scene)["total_energy"] - e0) / e0
        errors["energy_Linf"] = energy_dev / e0
    out = Outcome(dt=dt, steps=steps, particles=p.count, errors=errors, values=measured)
    out.step_seconds = stepper.seconds
    if not on_wall:
        momentum = (p.mass[:, None] * p.vel).sum(axis=0)
        out.drift["momentum"] = float(np.abs(momentum).max() / (p.mass.sum() * speed))
    return out, {"delta_max": elastic.delta_max, "F_max": elastic.force_max, "t_c": t_ref}


# Chung & Ooi (2011) tests 1 and 2: (E Pa, nu, rho kg/m^3, R m, speed m/s, on a wall) and the
# published F_max [N], delta_max [m], t_c [s]
CHUNG_OOI = {
    "glass": ((4.8e10, 0.20, 2800.0, 0.01, 10.0, False), (10.697e3, 274.1e-6, 40.34e-6)),
    "limestone": ((2.0e10, 0.25, 2500.0, 0.01, 10.0, False), (7.108e3, 368.3e-6, 54.20e-6)),
    "al-alloy": ((7.0e10, 0.30, 2699.0, 0.1, 0.2, True), (11.370e3, 49.72e-6, 731.7e-6)),
    "mg-alloy": ((4.0e10, 0.35, 1800.0, 0.1, 0.2, True), (7.233e3, 52.12e-6, 767.1e-6)),
}
HERTZ_LABELS = {
    "delta_max": "|delta_max - closed form| / closed form",
    "F_max": "|F_max - closed form| / closed form",
    "t_c": "|t_c - 2.9433 delta_max/v| / t_c",
    "L2": "overlap history, RMS error / delta_max (RK4 reference of x'' = -x^{3/2})",
    "Linf": "overlap history, max error / delta_max",
    "e": "|v_out/v_in - 1|",
    "published": "max over F_max, delta_max, t_c of |value - Chung & Ooi| / Chung & Ooi",
}


def chung_ooi(spc: float, material: str) -> Outcome:
    (youngs, poisson, density, radius, speed, on_wall), published = CHUNG_OOI[material]
    out, _ = hertz_impact(spc, youngs, poisson, density, radius, speed, on_wall)
    f_pub, d_pub, t_pub = published
    v = out.values
    out.errors["published"] = max(
        abs(v["F_max"] - f_pub) / f_pub, abs(v["delta_max"] - d_pub) / d_pub, abs(v["t_c"] - t_pub) / t_pub
    )
    return out


HERTZ_ORDER_NOTE = (
    "velocity Verlet is second order; the Hertz force (4/3) E* sqrt(R*) delta^{3/2} is continuous "
    "with a continuous first derivative at the touch, so the impact costs no order"
)


def _register_chung_ooi(material: str, test: int, title: str) -> None:
    (youngs, poisson, density, radius, speed, on_wall), (f_pub, d_pub, t_pub) = CHUNG_OOI[material]
    register(
        VerificationCase(
            name=f"a3-chung-ooi-{test}-{material}",
            title=f"A2/A3 Chung & Ooi test {test}: {title}",
            model="hertz",
            reference=(
                f"Chung & Ooi (2011), Granular Matter 13:643, test {test}: F_max = {f_pub / 1e3:g} kN, "
                f"delta_max = {d_pub * 1e6:g} um, t_c = {t_pub * 1e6:g} us; the order is measured "
                "against the closed forms of A2 (verification group A2, A3)"
            ),
            description=(
                f"E = {youngs:g} Pa, nu = {poisson}, rho = {density:g} kg/m^3, R = {radius} m, "
                + (f"sphere on a rigid plane at {speed} m/s" if on_wall else f"two spheres at +-{speed} m/s")
                + ", e = 1, gravity off, touch at mid-step"
            ),
            run=lambda spc: chung_ooi(spc, material),
            ladder=(25, 50, 100, 200, 400, 800),
            quick_ladder=(50, 100, 200),
            error_labels=HERTZ_LABELS,
            order_metrics=("t_c", "L2"),
            formal_order=2.0,
            min_order=1.8,
            order_note=HERTZ_ORDER_NOTE,
            tolerances=(
                Tolerance("published", 1e-2, 100, source=A3_SOURCE),
                Tolerance("delta_max", 1e-2, 100, source=A3_SOURCE),
                Tolerance("F_max", 1e-2, 100, source=A3_SOURCE),
                Tolerance("t_c", 1e-2, 100, source=A3_SOURCE),
                Tolerance("e", 1e-3, 100, source="A3: e = 1 rebounds at 1 +- 1e-3"),
            ),
            drift_bounds={} if on_wall else {"momentum": 1e-14},
        )
    )


_register_chung_ooi("glass", 1, "two glass spheres head-on at +-10 m/s")
_register_chung_ooi("limestone", 1, "two limestone spheres head-on at +-10 m/s")
_register_chung_ooi("al-alloy", 2, "aluminium-alloy sphere on a rigid plane at 0.2 m/s")
_register_chung_ooi("mg-alloy", 2, "magnesium-alloy sphere on a rigid plane at 0.2 m/s")


# ------------------------------------------------------------- A3 test 3: restitution


AL_OXIDE = (3.8e11, 0.23, 4000.0, 2.5e-3, 3.9)  # E, nu, rho, R, speed
RESTITUTIONS = (0.2, 0.4, 0.6, 0.8, 1.0)


def chung_ooi_restitution(spc: float) -> Outcome:
    """A3 test 3: an aluminium-oxide sphere on a rigid plane at 3.9 m/s with each requested e;
    the realised e (largest absolute deviation over the e values) and the contact time against
    the damped closed form (physics/restitution.hertz_contact_time)."""
    youngs, poisson, density, radius, speed = AL_OXIDE
    runs = [hertz_impact(spc, youngs, poisson, density, radius, speed, True, e=e)[0] for e in RESTITUTIONS]
    values = {f"e({e:g})": r.values["e"] for e, r in zip(RESTITUTIONS, runs, strict=True)}
    return Outcome(
        dt=runs[0].dt,
        steps=sum(r.steps for r in runs),
        particles=1,
        errors={
            "e": max(r.errors["e"] for r in runs[:-1]),
            "e_elastic": runs[-1].errors["e"],
            "t_c": max(r.errors["t_c"] for r in runs),
        },
        values=values,
        step_seconds=sum(r.step_seconds for r in runs),
    )


register(
    VerificationCase(
        name="a3-chung-ooi-3-restitution",
        title="A3 Chung & Ooi test 3: requested restitution 0.2 ... 1.0 (aluminium oxide on a plane)",
        model="hertz",
        reference=(
            "the measured e equals the requested e +- 0.02, e = 1 rebounds at 1 +- 1e-3 (Chung & Ooi "
            "2011 test 3; verification group A3); contact time from the dimensionless Tsuji-damped "
            "Hertz equation (physics/restitution.py)"
        ),
        description=(
            f"E = {AL_OXIDE[0]:g} Pa, nu = {AL_OXIDE[1]}, rho = {AL_OXIDE[2]:g} kg/m^3, R = {AL_OXIDE[3]} m, "
            f"{AL_OXIDE[4]} m/s onto a rigid plane, e = {', '.join(f'{e:g}' for e in RESTITUTIONS)} "
            "(steps summed over the five impacts), touch at mid-step"
        ),
        run=chung_ooi_restitution,
        ladder=(25, 50, 100, 200, 400, 800),
        quick_ladder=(50, 100, 200),
        error_labels={
            "e": "max over e < 1 of |e_realised - e_requested|",
            "e_elastic": "|e_realised - 1| at e = 1",
            "t_c": "max over e of |t_c - closed form| / closed form",
        },
        order_metrics=("e",),
        formal_order=1.25,
        min_order=None,
        order_note=(
            "the Tsuji dashpot c delta^{1/4} delta' switches on like t^{1/4} at the touch, which a fixed "
            "step integrates to O(dt^{5/4}); reported, not enforced"
        ),
        tolerances=(
            Tolerance("e", 2e-2, 100, source="A3: e as requested +- 0.02 (>= 100 steps per contact)"),
            Tolerance("e_elastic", 1e-3, 100, source="A3: e = 1 rebounds at 1 +- 1e-3"),
            Tolerance("t_c", 1e-2, 100, source=A3_SOURCE),
        ),
    )
)


# ------------------------------------------------------- A4: Hertz elastic energy order


def hertz_energy(spc: float) -> Outcome:
    (youngs, poisson, density, radius, speed, on_wall), _ = CHUNG_OOI["glass"]
    out, _ = hertz_impact(spc, youngs, poisson, density, radius, speed, on_wall, energy=True)
    out.drift["energy"] = out.errors["energy"]
    return out


register(
    VerificationCase(
        name="a4-elastic-energy-hertz",
        title="A4 elastic Hertz collision: energy error (glass spheres of A3 test 1)",
        model="hertz",
        reference=(
            "an elastic collision conserves energy; kinetic + (2/5) k_h delta^{5/2}; verification "
            "group A4: the energy error converges with order >= 1.8 in dt for Hertz (velocity Verlet)"
        ),
        description="two glass spheres (A3 test 1) at +-10 m/s, e = 1, energy measured every step",
        run=hertz_energy,
        ladder=(25, 50, 100, 200, 400, 800),
        quick_ladder=(50, 100, 200),
        error_labels={
            **HERTZ_LABELS,
            "energy": "|E_after - E_before| / E_before",
            "energy_Linf": "max over the run |E(t) - E_0| / E_0",
        },
        order_metrics=("energy", "energy_Linf"),
        formal_order=2.0,
        min_order=1.8,
        order_note=HERTZ_ORDER_NOTE,
        tolerances=(Tolerance("energy", 2e-3, 100, source="e = 1 +- 1e-3 (A3) means energy within 2e-3"),),
        drift_bounds={"momentum": 1e-14},
    )
)
