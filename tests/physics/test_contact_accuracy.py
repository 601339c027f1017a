"""Accuracy of a collision at the time step sphere chooses, wherever in a step the touch falls
(kernels/contact.py contact_window and normal_law): an elastic oblique impact in the sticking
regime converges at second order in dt to the analytic contact-velocity ratio and is within 1 %
at dt = "auto"; an elastic head-on collision (e = 1) rebounds at 1 within 1e-3 at dt = "auto",
linear and Hertz, on a wall and between two spheres."""

from __future__ import annotations

import math

import numpy as np
import pytest
from dem_physics_cases import advance, hertz_contact, make_scene, sphere_mass

from sphere_cli.verify.scenes import linear_contact

R = 1e-3
DENSITY = 2500.0
KN = 1e4
MASS = sphere_mass(R, DENSITY)
PHASES = (0.13, 0.37, 0.61, 0.89)  # where in a step the touch falls


def _oblique(tmp_path, phase: float, dt: float | str) -> tuple[float, float]:
    """(measured, analytic) ratio of the contact point's tangential velocity after and before a
    sphere hits a wall at 0.1 m/s with 0.05 m/s sideways: linear, e = 1, k_t = k_n/2, a friction
    coefficient no force reaches (sticking throughout). Analytic: the tangential spring turns the
    sphere too, omega_t^2 = k_t (1/m + R^2/I) = 3.5 k_t/m, for the contact time pi/omega_n, so
    the ratio is cos(omega_t pi/omega_n) = cos(pi sqrt(1.75)) = -0.524."""
    vz, vx = 0.1, 0.05
    probe = make_scene(tmp_path, [[0.05, 0.05, 2 * R]], R, kn=KN, kt=0.5 * KN, e=1.0, mu=1e6, walls=["z-"])
    step = probe.state.clock.dt if dt == "auto" else dt
    scene = make_scene(
        tmp_path,
        [[0.05, 0.05, R + vz * step * phase]],
        R,
        [[vx, 0.0, -vz]],
        kn=KN,
        kt=0.5 * KN,
        e=1.0,
        mu=1e6,
        walls=["z-"],
        dt=dt,
    )
    contact_time = math.pi / math.sqrt(KN / MASS)
    advance(scene, int(2 * contact_time / step) + 20)
    p = scene.state.particles
    assert p.vel[0, 2] > 0.0  # it has left the wall
    measured = (p.vel[0, 0] - R * p.angvel[0, 1]) / vx
    return measured, math.cos(contact_time * math.sqrt(3.5 * 0.5 * KN / MASS))


def _worst(tmp_path, dt) -> float:
    errors = []
    for phase in PHASES:
        measured, exact = _oblique(tmp_path, phase, dt)
        errors.append(abs(measured - exact) / abs(exact))
    return max(errors)


def test_oblique_sticking_impact_is_second_order_and_within_1_percent_at_auto(tmp_path):
    contact_time = math.pi / math.sqrt(KN / MASS)
    errors = [_worst(tmp_path, contact_time / steps) for steps in (20, 40, 80)]
    orders = [math.log2(a / b) for a, b in zip(errors, errors[1:], strict=False)]
    assert min(orders) >= 1.8, (errors, orders)  # first order (the old spring): 1.0
    assert _worst(tmp_path, "auto") <= 0.01


LAWS = {
    "linear": linear_contact(KN, 1.0, 0.5),
    "hertz": hertz_contact(1.0e7, 0.3, 1.0, 0.5),
}


@pytest.mark.parametrize("law", list(LAWS))
@pytest.mark.parametrize("partner", ["wall", "sphere"])
def test_an_elastic_collision_rebounds_at_one_at_auto(tmp_path, law, partner):
    v = 0.2
    worst = 0.0
    for phase in np.linspace(0.05, 0.95, 7):
        gap = 1e-6 + phase * 1e-5  # the touch at 7 places within a step
        if partner == "wall":
            pos, vel, walls = [[0.05, 0.05, R + gap]], [[0.0, 0.0, -v]], ["z-"]
        else:
            pos = [[0.05, 0.05, 0.05], [0.05, 0.05, 0.05 + 2 * R + gap]]
            vel, walls = [[0.0, 0.0, v / 2], [0.0, 0.0, -v / 2]], []
        scene = make_scene(tmp_path, pos, R, vel, contact=LAWS[law], walls=walls)
        advance(scene, int(3e-3 / scene.state.clock.dt))
        p = scene.state.particles
        after = p.vel[0, 2] if partner == "wall" else p.vel[1, 2] - p.vel[0, 2]
        assert after > 0.0  # apart again
        worst = max(worst, abs(after / v - 1.0))
    assert worst <= 1e-3  # without the touch and the parting placed within the step: 5e-3
