"""Accuracy of a collision at the time step sphere chooses, wherever in a step the touch falls
(kernels/contact.py contact_window and normal_law): an elastic oblique impact in the sticking
regime converges at second order in dt to the analytic contact-velocity ratio and is within 1 %
at dt = "auto", and a Hertz-Mindlin one converges to its law's own solution (order about 1.8)
within 1e-3 at "auto"; an elastic head-on collision (e = 1) rebounds at 1 within 1e-3 at dt = "auto",
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


# A Hertz-Mindlin sphere (alumina, Chung & Ooi's test 3 material) striking a rigid wall at 0.1
# m/s with 0.02 m/s sideways, elastic, sticking throughout
AL2O3 = (3.8e11, 0.23, 4000.0, 2.5e-3)  # E [Pa], nu, density [kg/m^3], R [m]


def _hertz_sticking_reference(vn: float, vt: float, n: int = 20000) -> tuple[float, float]:
    """(ratio of the contact point's tangential velocity after and before, contact time [s]) of
    the law as the user guide states it, integrated by RK4 in n steps of the Hertz contact time:
    m delta'' = -(4/3) E* sqrt(R) delta^(3/2), xi' = v_c, m v_c' = -3.5 k_t(delta) xi with
    k_t = 8 G* sqrt(R delta) (the spring xi follows the stiffness: force -k_t xi), against a
    rigid wall (E* = E/(1 - nu^2), G* = G/(2 - nu)). The RK4 result changes by 4e-8 from n to 2n."""
    e, nu, rho, r = AL2O3
    m = sphere_mass(r, rho)
    e_star, g_star = e / (1.0 - nu**2), e / (2.0 * (1.0 + nu)) / (2.0 - nu)
    kh = 4.0 / 3.0 * e_star * math.sqrt(r)
    contact_time = 2.9432 * (15.0 * m * vn**2 / (16.0 * e_star * math.sqrt(r))) ** 0.4 / vn
    h = contact_time / n

    def rate(y):
        depth = max(y[0], 0.0)
        return np.array([y[1], -kh * depth**1.5 / m, y[3], -28.0 * g_star * math.sqrt(r * depth) * y[2] / m])

    y = np.array([0.0, vn, 0.0, vt])
    while True:
        k1 = rate(y)
        k2 = rate(y + 0.5 * h * k1)
        k3 = rate(y + 0.5 * h * k2)
        nxt = y + h / 6.0 * (k1 + 2.0 * k2 + 2.0 * k3 + rate(y + h * k3))
        if nxt[0] < 0.0 < y[0] and y[1] < 0.0:  # the overlap closes within this step
            w = y[0] / (y[0] - nxt[0])
            return (y[3] + w * (nxt[3] - y[3])) / vt, contact_time
        y = nxt


def _hertz_oblique(tmp_path, phase: float, dt: float | str, vn: float, vt: float, duration: float) -> float:
    e, nu, rho, r = AL2O3
    law = hertz_contact(e, nu, 1.0, 1e6)
    probe = make_scene(tmp_path, [[0.05, 0.05, 2 * r]], r, density=rho, contact=law, walls=["z-"], dt=dt)
    step = probe.state.clock.dt
    scene = make_scene(
        tmp_path, [[0.05, 0.05, r + vn * step * phase]], r, [[vt, 0.0, -vn]],
        density=rho, contact=law, walls=["z-"], dt=dt,
    )  # fmt: skip
    advance(scene, int(1.3 * duration / step) + 20)
    p = scene.state.particles
    assert p.vel[0, 2] > 0.0  # it has left the wall
    return (p.vel[0, 0] - r * p.angvel[0, 1]) / vt


def test_hertz_oblique_sticking_impact_converges_to_its_law(tmp_path):
    """The Hertz-Mindlin tangential spring in the sticking regime (no test of the linear law
    reaches its overlap-dependent stiffness): the contact point's tangential velocity ratio
    converges to the law's own solution (_hertz_sticking_reference, 1.0135: the spring's energy
    is not kept as its stiffness falls while the overlap closes), the worst over where in a step
    the touch falls, and is within 1e-3 of it at dt = "auto" (about 180 steps a contact; 4e-5
    measured). The order is about 1.8, not 2: k_t grows as sqrt(delta) from the touch and falls
    so to the parting, a kink no step resolves (measured 1.77-1.83 per phase from 40 to 1280 steps
    a contact; as the A4 energy error of a Hertz collision, order >= 1.8); a spring that lags by
    a step converges at order 1."""
    vn, vt = 0.1, 0.02
    exact, contact_time = _hertz_sticking_reference(vn, vt)

    def worst(dt) -> float:
        ratios = [_hertz_oblique(tmp_path, phase, dt, vn, vt, contact_time) for phase in PHASES]
        return max(abs(ratio / exact - 1.0) for ratio in ratios)

    errors = [worst(contact_time / steps) for steps in (80, 160, 320, 640)]
    orders = [math.log2(a / b) for a, b in zip(errors, errors[1:], strict=False)]
    assert min(orders) >= 1.7, (errors, orders)
    assert worst("auto") <= 1e-3


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
