"""A2, A3 and the Hertz part of A4: Hertz-Mindlin impacts (verification groups).

A2: the elastic Hertz impact, delta_max = (15 m* v^2/(16 E* sqrt(R*)))^{2/5},
F_max = (4/3) E* sqrt(R*) delta_max^{3/2}, t_c = 2.9433 delta_max/v (Hertz 1882; Johnson,
Contact Mechanics, 1985, section 11.4). A3: Chung & Ooi (2011), Granular Matter 13:643, tests 1-3.
A4: oblique impact in gross sliding, and the energy error of an elastic collision converging with
order >= 1.8 in dt.

Every impact starts a few steps of free flight before the touch (free flight is exact in velocity
Verlet) and is measured step by step: the overlap from the positions, the normal force from the
force array (gravity is off), the end of contact where the overlap returns to zero, interpolated
linearly between the last two steps (the overlap is linear in time there, so this is exact to
O(dt^2)).
"""

from __future__ import annotations

import numpy as np
import pytest
from dem_physics_cases import advance, hertz_contact, hertz_reference, make_scene, sphere_mass

from sphere_cli.physics.observe.energy import observables

LEAD_STEPS = 3


def impact(
    tmp_path,
    youngs_modulus,
    poisson_ratio,
    density,
    radius,
    speed,
    on_wall,
    *,
    e=1.0,
    mu=0.0,
    steps_per_contact=100,
    phase=0.3,
    tangential_speed=0.0,
    wall_material=None,
):
    """One head-on (or oblique) impact of two equal spheres at +-speed, or of a sphere at `speed`
    on the rigid z- wall (or a wall of `wall_material`, a [[materials]] dict). dt is the elastic
    A2 duration / steps_per_contact; the touch falls `phase` of the way into a step.
    Returns a dict of measured quantities and the scene."""
    m = sphere_mass(radius, density)
    if on_wall:
        m_eff, r_eff, v = m, radius, speed
        e_star = youngs_modulus / (1.0 - poisson_ratio**2)
    else:
        m_eff, r_eff, v = 0.5 * m, 0.5 * radius, 2.0 * speed
        e_star = youngs_modulus / (2.0 * (1.0 - poisson_ratio**2))
    ref = hertz_reference(e_star, r_eff, m_eff, v)
    dt = ref["contact_time"] / steps_per_contact
    t_touch = (LEAD_STEPS + phase) * dt
    gap = v * t_touch
    side = 20.0 * radius
    c = 0.5 * side
    contact = hertz_contact(youngs_modulus, poisson_ratio, e, mu)
    if on_wall:
        pos = [[c, c, radius + gap]]
        vel = [[tangential_speed, 0.0, -speed]]
        materials, particle_material, walls = (), None, {}
        if wall_material is not None:
            particle = {"name": "ball", "density": density}
            materials, particle_material, walls = (
                [particle, wall_material],
                "ball",
                {"z-": wall_material["name"]},
            )
        scene = make_scene(
            tmp_path,
            pos,
            radius,
            vel,
            density=density,
            contact=contact,
            walls=["z-"],
            dt=dt,
            upper=(side, side, side),
            materials=materials,
            particle_material=particle_material,
            wall_material=walls,
        )
    else:
        pos = [[c - radius - 0.5 * gap, c, c], [c + radius + 0.5 * gap, c, c]]
        vel = [[speed, 0.0, 0.0], [-speed, 0.0, 0.0]]
        scene = make_scene(
            tmp_path, pos, radius, vel, density=density, contact=contact, dt=dt, upper=(side, side, side)
        )
    p = scene.state.particles

    def overlap():
        return radius - p.pos[0, 2] if on_wall else 2.0 * radius - (p.pos[1, 0] - p.pos[0, 0])

    energy0 = observables(scene)["total_energy"]
    forces, overlaps, energy_drift = [], [], 0.0
    previous = overlap()
    steps_in_contact = 0
    for _ in range(LEAD_STEPS + 5 * steps_per_contact):
        advance(scene, 1)
        now = overlap()
        if now > 0.0:
            steps_in_contact += 1
            forces.append(p.force[0, 2] if on_wall else -p.force[0, 0])
            overlaps.append(now)
            energy_drift = max(energy_drift, abs(observables(scene)["total_energy"] / energy0 - 1.0))
        elif previous > 0.0:
            break
        previous = now
    else:
        raise AssertionError("the contact did not end")
    t_end = (scene.state.clock.step - 1) * dt + dt * previous / (previous - now)
    v_out = p.vel[0, 2] if on_wall else p.vel[1, 0] - p.vel[0, 0]
    return {
        "ref": ref,
        "scene": scene,
        "dt": dt,
        "steps": steps_in_contact,
        "force_max": max(forces),
        "delta_max": max(overlaps),
        "contact_time": t_end - t_touch,
        "restitution": v_out / v,
        "energy_drift": energy_drift,
    }


# ------------------------------------------------------------------------------------ A2


@pytest.mark.parametrize("on_wall", [False, True], ids=["sphere-sphere", "sphere-wall"])
def test_hertz_elastic_impact(tmp_path, on_wall):
    """A2: delta_max, F_max and t_c = 2.9433 delta_max/v of an elastic Hertz impact, at 100 steps
    per contact, within 1e-3; the rebound speed equals the impact speed and the energy
    (kinetic + the Hertz elastic energy (8/15) E* sqrt(R*) delta^{5/2}) is conserved through
    the contact, both within 1e-3.

    Tolerance: sampling the peak at the nearest step misses it by at most dt/2, a relative error
    (pi dt/(2 t_c))^2/2 = 1.2e-4 at 100 steps; velocity Verlet's O(dt^2) error is of the same
    size (measured: -0.9e-5 on F_max, -0.6e-5 on delta_max, -5e-5 on t_c; -1.4e-4 on F_max
    when the touch falls at mid-step). 1e-3 is 10x tighter than A3's 1 % and still 7x the
    largest measured error.
    """
    r = impact(tmp_path, 1.0e8, 0.3, 2500.0, 1.0e-3, 0.5, on_wall)
    assert r["steps"] >= 99
    for key in ("delta_max", "force_max", "contact_time"):
        assert r[key] == pytest.approx(r["ref"][key], rel=1e-3), key
    assert r["restitution"] == pytest.approx(1.0, abs=1e-3)
    assert r["energy_drift"] < 1e-3


# ------------------------------------------------------------------------------- A3 tests 1, 2

CHUNG_OOI = {
    # name: (E [Pa], nu, rho [kg/m^3], R [m], speed [m/s], on a rigid wall, F_max [N], delta_max [m], t_c [s])
    "test1-glass": (4.8e10, 0.20, 2800.0, 0.010, 10.0, False, 10.697e3, 274.1e-6, 40.34e-6),
    "test1-limestone": (2.0e10, 0.25, 2500.0, 0.010, 10.0, False, 7.108e3, 368.3e-6, 54.20e-6),
    "test2-Al-alloy": (7.0e10, 0.30, 2699.0, 0.10, 0.2, True, 11.370e3, 49.72e-6, 731.7e-6),
    "test2-Mg-alloy": (4.0e10, 0.35, 1800.0, 0.10, 0.2, True, 7.233e3, 52.12e-6, 767.1e-6),
}


@pytest.mark.parametrize("name", list(CHUNG_OOI))
def test_chung_ooi_elastic_normal_impact(tmp_path, name):
    """A3, Chung & Ooi (2011) test 1 (two equal spheres head-on at +-10 m/s, glass and limestone)
    and test 2 (a sphere on a rigid plane at 0.2 m/s, Al and Mg alloy), gravity off, elastic:
    F_max, delta_max and t_c within the 1 % of A3 at 100 steps per contact (A3 asks >= 100).
    The published figures carry 4-5 digits, so they are checked at A3's 1 %; the discretisation
    error itself is ~1e-4 (see test_hertz_elastic_impact)."""
    E, nu, rho, radius, speed, on_wall, force, delta, duration = CHUNG_OOI[name]
    r = impact(tmp_path, E, nu, rho, radius, speed, on_wall)
    assert r["steps"] >= 99
    assert r["dt"] < r["scene"].dt_limit
    assert r["force_max"] == pytest.approx(force, rel=0.01)
    assert r["delta_max"] == pytest.approx(delta, rel=0.01)
    assert r["contact_time"] == pytest.approx(duration, rel=0.01)
    assert r["restitution"] == pytest.approx(1.0, abs=1e-3)


# ----------------------------------------------------------------------------------- A3 test 3

AL_OXIDE = {"name": "alumina", "youngs_modulus": 3.8e11, "poisson_ratio": 0.23}


@pytest.mark.parametrize("e", [0.2, 0.4, 0.6, 0.8, 1.0])
def test_chung_ooi_restitution(tmp_path, e):
    """A3, Chung & Ooi (2011) test 3: an Al oxide sphere (E = 380 GPa, nu = 0.23, 4000 kg/m^3,
    R = 2.5 mm) hits an Al oxide plane (a wall of that material) at 3.9 m/s with the restitution
    set to e: the rebound is e within 0.02 (A3), and within 1e-3 for e = 1.

    The Tsuji dashpot is calibrated in closed form for the clamped contact (physics/restitution.py,
    c_h = sqrt5 zeta(e)); at >= 100 steps per contact and a touch 0.3 of the way into a step the
    measured error is <= 2e-4 for every e (4e-6 at e = 1; <= 9e-4 for other phases of the
    touch), so 0.02 is A3's bound, not a margin chosen for this code."""
    r = impact(tmp_path, 3.8e11, 0.23, 4000.0, 2.5e-3, 3.9, True, e=e, wall_material=AL_OXIDE)
    assert r["steps"] >= 100  # the elastic plane makes the contact longer than the dt reference
    assert r["restitution"] == pytest.approx(e, abs=0.02)
    if e == 1.0:
        assert r["restitution"] == pytest.approx(1.0, abs=1e-3)


# ------------------------------------------------------------------------ A4: oblique impact


@pytest.mark.parametrize("e", [0.5, 1.0])
def test_oblique_hertz_impact_in_gross_sliding(tmp_path, e):
    """A4: in an oblique impact that slides throughout, the centre's tangential velocity changes
    by -mu (1+e) v_n and the spin by (5/2) mu (1+e) v_n/R (any normal law; here Hertz-Mindlin,
    whose Mindlin spring k_t = 8 G* sqrt(R* delta) must saturate at mu F_n at once).

    Gross sliding: v_t = 2 m/s > (7/2) mu (1+e) v_n = 0.42 m/s. With the force capped at mu F_n
    throughout, the tangential impulse is exactly mu times the normal one m (1 + e_real) v_n, to
    round-off (1e-12: sums of ~100 increments); with the requested e to A4's 1 % (e is realised
    within 1e-3, see test_chung_ooi_restitution)."""
    mu, vn, vt, radius = 0.3, 0.2, 2.0, 1.0e-3
    r = impact(tmp_path, 1.0e8, 0.3, 2500.0, radius, vn, True, e=e, mu=mu, tangential_speed=vt, phase=0.37)
    p = r["scene"].state.particles
    e_real = r["restitution"]
    dv_t = p.vel[0, 0] - vt
    spin = p.angvel[0, 1]
    assert p.vel[0, 0] - radius * spin > 0.0  # still sliding at the end
    assert dv_t == pytest.approx(-mu * (1.0 + e_real) * vn, rel=1e-12)
    assert spin == pytest.approx(2.5 * mu * (1.0 + e_real) * vn / radius, rel=1e-12)
    assert dv_t == pytest.approx(-mu * (1.0 + e) * vn, rel=0.01)
    assert spin == pytest.approx(2.5 * mu * (1.0 + e) * vn / radius, rel=0.01)
    np.testing.assert_array_equal(p.angvel[0, [0, 2]], 0.0)


# ------------------------------------------------------------ A4: energy error convergence


def test_elastic_hertz_collision_energy_converges_at_second_order(tmp_path):
    """A4: the energy error of an elastic Hertz collision (the glass pair of Chung & Ooi test 1)
    shrinks with observed order >= 1.8 in dt (velocity Verlet is second order; the Hertz force
    delta^{3/2} is not smooth at the touch, which is why A4 asks 1.8 rather than 2).

    The error is |v_out^2/v_in^2 - 1| after the contact, at 25, 50, 100 and 200 steps per contact.
    The touch falls at the same fraction (0.3) of a step for every dt, so the sequence measures the
    scheme's order and not the phase of the touch, which would scatter the errors (a touch at
    mid-step happens to cancel the leading term: order 3.5 there). The order is the
    least-squares slope of log(error) against log(dt) (measured: 2.5)."""
    steps = np.array([25, 50, 100, 200])
    errors = []
    for n in steps:
        r = impact(tmp_path, 4.8e10, 0.2, 2800.0, 0.01, 10.0, False, steps_per_contact=int(n))
        errors.append(abs(r["restitution"] ** 2 - 1.0))
    order = np.polyfit(np.log(1.0 / steps), np.log(errors), 1)[0]
    assert order >= 1.8, f"observed order {order:.2f}, errors {errors}"
    assert errors[-1] < 1e-5
