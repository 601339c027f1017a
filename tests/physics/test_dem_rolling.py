"""Rolling resistance, constant-torque model (Ai, Chen, Rotter & Ooi 2011, Powder Technol. 206:269,
model type A): a torque M = -mu_r R* F_n w_r/|w_r| against the relative rolling w_r, never
reversing it within a step (kernels/contact.py).

A sphere rolling without slip on a floor (normal force m g, R* = R for a wall), friction force F
along the motion at the contact point -R z, rolling torque mu_r R m g against the spin:
    m dv/dt = F,   I dw/dt = -R F - mu_r R m g,   v = w R (no slip),   I = (2/5) m R^2
gives (I/R^2 + m) dv/dt = -mu_r m g, i.e.
    dv/dt = -(5/7) mu_r g,
constant until the sphere stops at t_stop = 7 v0/(5 mu_r g) after rolling v0^2/(2 (5/7) mu_r g);
it then stays at rest (the torque only opposes rolling). This is the rolling analogue of A4's
"sphere on an incline": there g sin(theta) drives, here the
torque brakes, with the same factor 5/7 from I = (2/5) m R^2.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from dem_physics_cases import advance, hertz_contact, make_scene, sphere_mass

from sphere_cli.kernels.laws import K_T

R = 1.0e-3  # m
DENSITY = 2500.0  # kg/m^3
MASS = sphere_mass(R, DENSITY)
INERTIA = 0.4 * MASS * R**2
G = 9.81  # m/s^2
V0 = 0.02  # m/s


def _rolling_sphere(tmp_path, law: str, mu_r: float):
    """A sphere at its static overlap on the z- floor, rolling without slip at V0 along x."""
    if law == "hertz":
        youngs, poisson = 1.0e8, 0.3
        k_h = 4.0 / 3.0 * youngs / (1.0 - poisson**2) * math.sqrt(R)
        z0 = R - (MASS * G / k_h) ** (2.0 / 3.0)
        contact = hertz_contact(youngs, poisson, 0.5, 0.5, rolling_friction=mu_r)
    else:
        kn = 1.0e3
        z0 = R - MASS * G / kn
        contact = {
            "model": "linear",
            "normal_stiffness": kn,
            "restitution": 0.5,
            "friction": 0.5,
            "rolling_friction": mu_r,
        }
    scene = make_scene(
        tmp_path,
        [[0.01, 0.05, z0]],
        R,
        [[V0, 0.0, 0.0]],
        contact=contact,
        walls=["z-"],
        gravity=(0.0, 0.0, -G),
        upper=(0.2, 0.1, 0.1),
    )
    scene.state.particles.angvel[0, 1] = V0 / R  # no slip: the contact point is at rest
    return scene


@pytest.mark.parametrize("law", ["linear", "hertz"])
def test_rolling_sphere_decelerates_at_five_sevenths_mu_r_g_and_stops(tmp_path, law):
    """A sphere rolling at v0 with rolling friction mu_r = 0.1 decelerates at (5/7) mu_r g (1 %,
    A4's tolerance; constant acceleration is integrated exactly: measured 4e-10 linear, 2e-13
    Hertz), keeps rolling without slip, stops at t_stop = 7 v0/(5 mu_r g) after the distance
    v0^2/(2 a) (1 % each; measured 4e-4 linear, 3e-5 Hertz: the stop falls inside one step,
    dt = 6e-4 t_stop linear, 5e-5 t_stop Hertz), and stays stopped: from
    1.05 t_stop on it only rings on its tangential spring, which carried the braking friction
    force m a and now releases it: speed below a sqrt(3.5 m/k_t), the amplitude of that release
    (3.5: the tangential mode moves centre and spin; measured 3 % of it), and at 1.5 t_stop it
    is at rest (speed and spin below 1e-9 v0; measured < 1e-30)."""
    mu_r = 0.1
    scene = _rolling_sphere(tmp_path, law, mu_r)
    p, dt = scene.state.particles, scene.state.clock.dt
    a = 5.0 / 7.0 * mu_r * G
    t_stop = V0 / a
    x0 = p.pos[0, 0]
    steps = int(1.5 * t_stop / dt)
    t, x, v, slip = np.empty(steps), np.empty(steps), np.empty(steps), np.empty(steps)
    for k in range(steps):
        advance(scene, 1)
        t[k], x[k], v[k] = scene.state.clock.time, p.pos[0, 0], p.vel[0, 0]
        slip[k] = p.vel[0, 0] - R * p.angvel[0, 1]
    rolling = (t > 0.1 * t_stop) & (t < 0.9 * t_stop)
    assert np.polyfit(t[rolling], v[rolling], 1)[0] == pytest.approx(-a, rel=0.01)
    assert np.abs(slip[rolling]).max() < 1e-6 * V0
    k = int(np.argmax(v <= 0.0))  # first step at or past the stop
    t_measured = t[k - 1] + dt * v[k - 1] / (v[k - 1] - v[k])
    assert t_measured == pytest.approx(t_stop, rel=0.01)
    after = t > 1.05 * t_stop
    assert after.sum() > 0.25 * steps
    assert x[after][0] - x0 == pytest.approx(V0**2 / (2.0 * a), rel=0.01)
    # released braking force m a on the tangential spring: speed amplitude a sqrt(3.5 m/k_t)
    k_t = scene.tables.wall_table[0, 0, K_T]
    if law == "hertz":
        k_t *= math.sqrt(R * (R - p.pos[0, 2]))
    assert np.abs(v[after]).max() < a * math.sqrt(3.5 * MASS / k_t)
    assert abs(v[-1]) < 1e-9 * V0 and abs(p.angvel[0, 1]) * R < 1e-9 * V0


@pytest.mark.parametrize("law", ["linear", "hertz"])
def test_without_rolling_friction_the_sphere_keeps_rolling(tmp_path, law):
    """mu_r = 0 (the default) is no resistance at all: the sphere rolls on at v0 and w = v0/R to
    round-off (1e-12) over the time it would have needed to stop with mu_r = 0.1."""
    scene = _rolling_sphere(tmp_path, law, 0.0)
    assert not scene.contact.rolling  # absent from the kernel work
    p = scene.state.particles
    t_stop = V0 / (5.0 / 7.0 * 0.1 * G)
    advance(scene, int(t_stop / scene.state.clock.dt))
    assert p.vel[0, 0] == pytest.approx(V0, rel=1e-12)
    assert R * p.angvel[0, 1] == pytest.approx(V0, rel=1e-12)


def test_rolling_resistance_between_spheres_is_a_couple_that_stops_relative_rolling(tmp_path):
    """Between two spheres the rolling torque acts on the relative rotation w_i - w_j as an equal
    and opposite couple (no force; R* = R/2 for equal spheres).

    A ring of three equal spheres in a box periodic along x, each overlapping its two
    neighbours by delta (so every normal force is k_n delta and the ring is in equilibrium),
    frictionless, gravity off. Sphere 0 spins at w0 about z; the others are still. Each of its
    two contacts brakes it with mu_r (R/2) k_n delta, and spins up its partner by the same, so
    w0 - w1 falls at 3 mu_r (R/2) k_n delta/I and reaches 0 at t* = w0 I/(3 mu_r (R/2) k_n delta)
    (1 %; dt ~ 1e-3 t*), after which all three spin together at w0/3 (1e-9) and stay so. The
    total spin is conserved throughout to round-off (1e-12), and the centres do not move."""
    kn, delta, mu_r, w0 = 1.0e3, 1.0e-5, 1.0e-3, 100.0
    spacing = 2.0 * R - delta
    length = 3.0 * spacing
    pos = [[(k + 0.5) * spacing, 0.005, 0.005] for k in range(3)]
    contact = {
        "model": "linear",
        "normal_stiffness": kn,
        "restitution": 0.5,
        "friction": 0.0,
        "rolling_friction": mu_r,
    }
    scene = make_scene(
        tmp_path,
        pos,
        R,
        contact=contact,
        upper=(length, 0.01, 0.01),
        periodic=(True, False, False),
        overlap_tolerance=0.1,
    )
    p, dt = scene.state.particles, scene.state.clock.dt
    p.angvel[0, 2] = w0
    torque = mu_r * 0.5 * R * kn * delta
    t_star = w0 * INERTIA / (3.0 * torque)
    assert t_star > 500 * dt
    x0 = p.pos.copy()
    steps = int(1.5 * t_star / dt)
    t, rel = np.empty(steps), np.empty(steps)
    for k in range(steps):
        advance(scene, 1)
        t[k], rel[k] = scene.state.clock.time, p.angvel[0, 2] - p.angvel[1, 2]
        assert p.angvel[:, 2].sum() == pytest.approx(w0, rel=1e-12)
    k = int(np.argmax(rel <= 0.0))
    t_measured = t[k - 1] + dt * rel[k - 1] / (rel[k - 1] - rel[k])
    assert t_measured == pytest.approx(t_star, rel=0.01)
    early = t < 0.5 * t_star
    assert np.polyfit(t[early], rel[early], 1)[0] == pytest.approx(-3.0 * torque / INERTIA, rel=0.01)
    np.testing.assert_allclose(p.angvel[:, 2], w0 / 3.0, rtol=1e-9)
    np.testing.assert_array_equal(p.angvel[:, :2], 0.0)
    np.testing.assert_allclose(p.pos, x0, rtol=0, atol=1e-12 * R)
