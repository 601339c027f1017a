"""Restitution calibration of the clamped linear and Hertz-Tsuji normal contacts.

Checks against direct integration of the equations of motion (verification group A1-A3):
clamped linear spring-dashpot (Schwager & Poeschel 2007) and Hertz with the Tsuji dashpot.
"""

import ast
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sphere_cli.kernels.restitution import hertz_contact_dimensionless
from sphere_cli.kernels.restitution import hertz_restitution as hertz_restitution_kernel
from sphere_cli.physics.restitution import (
    HERTZ_ELASTIC_CONTACT_TIME_FACTOR,
    LINEAR_CRITICAL_RESTITUTION,
    hertz_contact_time,
    hertz_damping_coefficient,
    hertz_restitution,
    hertz_restitution_integrated,
    hertz_stiffness,
    linear_contact_time,
    linear_damping_ratio,
    linear_damping_ratio_unclamped,
    linear_restitution,
)

ROOT = Path(__file__).resolve().parents[2]


# ---------------------------------------------------------------- linear spring-dashpot


def integrate_clamped_linear(zetas, h=2.0e-4):
    """RK4 of x'' = -max(0, x + 2 zeta x') (omega0 = 1, x(0) = 0, x'(0) = 1) for an array of
    zetas at once; returns (e, t_end) located by linear interpolation of the force."""
    zeta = np.asarray(zetas, dtype=float)
    x = np.zeros_like(zeta)
    v = np.ones_like(zeta)
    t = 0.0
    e = np.full_like(zeta, np.nan)
    t_end = np.full_like(zeta, np.nan)
    active = np.ones(zeta.shape, dtype=bool)

    def acc(x, v):
        return -np.maximum(0.0, x + 2.0 * zeta * v)

    while active.any():
        k1x, k1v = v, acc(x, v)
        k2x, k2v = v + 0.5 * h * k1v, acc(x + 0.5 * h * k1x, v + 0.5 * h * k1v)
        k3x, k3v = v + 0.5 * h * k2v, acc(x + 0.5 * h * k2x, v + 0.5 * h * k2v)
        k4x, k4v = v + h * k3v, acc(x + h * k3x, v + h * k3v)
        x1 = x + h / 6.0 * (k1x + 2 * k2x + 2 * k3x + k4x)
        v1 = v + h / 6.0 * (k1v + 2 * k2v + 2 * k3v + k4v)
        f0 = x + 2.0 * zeta * v
        f1 = x1 + 2.0 * zeta * v1
        ended = active & (f1 <= 0.0)
        s = f0[ended] / (f0[ended] - f1[ended])
        e[ended] = -(v[ended] + s * (v1[ended] - v[ended]))
        t_end[ended] = t + s * h
        active &= ~ended
        x, v, t = x1, v1, t + h
        assert t < 20.0
    return e, t_end


ZETAS = [0.0, 0.05, 0.2, 0.45594981, 1.0 / math.sqrt(2.0), 0.9, 0.99, 1.0, 1.5, 3.0]


def test_closed_form_matches_integrated_clamped_linear_ode():
    e_num, t_num = integrate_clamped_linear(ZETAS)
    for zeta, e, t in zip(ZETAS, e_num, t_num, strict=True):
        assert linear_restitution(zeta) == pytest.approx(e, abs=1e-6), zeta
        assert linear_contact_time(1.0, 1.0, zeta) == pytest.approx(t, abs=1e-6), zeta


def test_closed_form_matches_the_atan2_expression():
    # e = exp(-zeta w0 t_end)|cos(w t_end) - zeta/s sin(w t_end)|, tan(w t) = -2 zeta s/(1-2zeta^2)
    for zeta in np.linspace(0.0, 0.999, 200):
        s = math.sqrt(1.0 - zeta**2)
        wt = math.atan2(2.0 * zeta * s, 2.0 * zeta**2 - 1.0)
        e = math.exp(-zeta * wt / s) * abs(math.cos(wt) - zeta / s * math.sin(wt))
        assert linear_restitution(zeta) == pytest.approx(e, rel=1e-12)
        assert linear_contact_time(4.0, 1.0, zeta) == pytest.approx(wt / (2.0 * s), rel=1e-12)


@pytest.mark.parametrize("asked, realised", [(0.2, 0.325), (0.5, 0.550), (0.8, 0.808)])
def test_textbook_damping_gives_higher_restitution_when_clamped(asked, realised):
    zeta = linear_damping_ratio_unclamped(asked)
    assert linear_restitution(zeta, clamped=False) == pytest.approx(asked, rel=1e-12)
    assert linear_restitution(zeta) == pytest.approx(realised, abs=0.002)


def test_linear_round_trip():
    for e in list(np.linspace(0.1, 1.0, 91)) + [1e-6, 0.01, 0.05, 0.135, 0.1354, 0.999999]:
        zeta = linear_damping_ratio(e)
        assert linear_restitution(zeta) == pytest.approx(e, rel=1e-10, abs=1e-12)
    assert linear_damping_ratio(LINEAR_CRITICAL_RESTITUTION) == pytest.approx(1.0, abs=1e-12)


def test_linear_exact_and_limit_values():
    assert linear_damping_ratio(1.0) == 0.0
    assert linear_damping_ratio_unclamped(1.0) == 0.0
    assert linear_restitution(0.0) == 1.0
    assert linear_restitution(1.0) == pytest.approx(math.exp(-2.0), rel=1e-15)
    assert linear_restitution(1.0 - 1e-9) == pytest.approx(math.exp(-2.0), rel=1e-8)
    assert linear_restitution(1.0 + 1e-9) == pytest.approx(math.exp(-2.0), rel=1e-8)
    assert linear_restitution(1e4) == pytest.approx(1.0 / (4.0 * 1e8), rel=1e-6)
    assert linear_restitution(1.5, clamped=False) == 0.0
    zetas = np.linspace(0.0, 5.0, 2001)
    assert np.all(np.diff([linear_restitution(z) for z in zetas]) < 0.0)


def test_overdamped_needed_below_critical_restitution():
    zeta = linear_damping_ratio(0.05)
    assert zeta > 1.0
    assert linear_restitution(zeta) == pytest.approx(0.05, rel=1e-12)
    with pytest.raises(ValueError, match="below the smallest the clamped linear contact"):
        linear_damping_ratio(0.05, allow_overdamped=False)
    assert linear_damping_ratio(0.2, allow_overdamped=False) < 1.0


def test_linear_contact_time():
    k, m = 2.0e5, 3.0e-3
    w0 = math.sqrt(k / m)
    assert linear_contact_time(k, m, 0.0) == pytest.approx(math.pi / w0, rel=1e-15)
    assert linear_contact_time(k, m, 0.3, clamped=False) == pytest.approx(
        math.pi / (w0 * math.sqrt(1 - 0.09)), rel=1e-15
    )
    assert linear_contact_time(k, m, 0.3) < linear_contact_time(k, m, 0.3, clamped=False)
    assert linear_contact_time(k, m, 1.0) == pytest.approx(2.0 / w0, rel=1e-15)
    assert linear_contact_time(k, m, 1.0, clamped=False) == math.inf
    with pytest.raises(ValueError):
        linear_contact_time(-1.0, m, 0.1)


@pytest.mark.parametrize("bad", [0.0, -0.1, 1.0000001, 2.0, math.nan, math.inf])
def test_restitution_out_of_range(bad):
    for func in (linear_damping_ratio, linear_damping_ratio_unclamped, hertz_damping_coefficient):
        with pytest.raises(ValueError, match="restitution"):
            func(bad)


# ---------------------------------------------------------------- Hertz with Tsuji damping


def test_hertz_elastic():
    assert hertz_damping_coefficient(1.0) == 0.0
    assert hertz_restitution(0.0) == 1.0
    e, tau, x_max = hertz_contact_dimensionless(0.0, 1e-3)
    assert e == pytest.approx(1.0, abs=1e-10)
    assert x_max == pytest.approx(1.25**0.4, rel=1e-12)
    assert tau / x_max == pytest.approx(2.9433, abs=1e-4)
    assert tau / x_max == pytest.approx(HERTZ_ELASTIC_CONTACT_TIME_FACTOR, rel=1e-10)


def test_hertz_elastic_contact_time_matches_chung_ooi():
    # verification group A3 test 2: Al alloy sphere on a rigid plane, t_c = 731.7 us
    young, nu, rho, radius, v = 7.0e10, 0.30, 2699.0, 0.1, 0.2
    e_star = young / (1.0 - nu**2)
    mass = rho * 4.0 / 3.0 * math.pi * radius**3
    delta_max = (15.0 * mass * v**2 / (16.0 * e_star * math.sqrt(radius))) ** 0.4
    t_c = hertz_contact_time(mass, hertz_stiffness(e_star, radius), v)
    assert t_c == pytest.approx(2.9433 * delta_max / v, rel=1e-4)
    assert t_c == pytest.approx(731.7e-6, rel=2e-3)
    assert delta_max == pytest.approx(49.72e-6, rel=2e-3)


def test_hertz_kernel_matches_closed_form():
    for c in [1e-3, 0.05, 0.3, 1.0, 2.0, math.sqrt(5.0), 3.0, 10.0, 100.0, 1e3]:
        assert hertz_restitution_integrated(c) == pytest.approx(hertz_restitution(c), rel=1e-10)
    assert hertz_restitution(3.0) == pytest.approx(5.0**-1.5, rel=1e-13)
    assert hertz_restitution(math.sqrt(5.0)) == pytest.approx(math.exp(-2.0), rel=1e-13)


def test_hertz_kernel_converges_fourth_order():
    ref = hertz_restitution_kernel(1.0, 1e-4)
    err = [abs(hertz_restitution_kernel(1.0, h) - ref) for h in (0.04, 0.02)]
    assert err[0] / err[1] > 12.0


def test_hertz_round_trip_and_cache():
    for e in list(np.linspace(0.1, 1.0, 46)) + [1e-4, 0.01, 0.05]:
        c = hertz_damping_coefficient(e)
        assert hertz_restitution(c) == pytest.approx(e, rel=1e-10, abs=1e-12)
        assert hertz_restitution_integrated(c) == pytest.approx(e, rel=1e-9)
    hits = hertz_damping_coefficient.cache_info().hits
    hertz_damping_coefficient(0.5)
    assert hertz_damping_coefficient.cache_info().hits == hits + 1


def integrate_dimensional_hertz(mass, k_h, c_h, v0, steps_per_unit=4000):
    """Pure-Python RK4 of m d'' = -max(0, k d^{3/2} + c_h sqrt(m k) d^{1/4} d') in SI units;
    returns |v_out|/v0 with the end located where the unclamped force changes sign."""
    damp = c_h * math.sqrt(mass * k_h)
    t_scale = (mass * v0**2 / k_h) ** 0.4 / v0
    dt = t_scale / steps_per_unit

    def force(d, u):
        return k_h * d**1.5 + damp * d**0.25 * u if d > 0.0 else 0.0

    def acc(d, u):
        return -max(0.0, force(d, u)) / mass

    d, u = 0.0, v0
    for _ in range(100 * steps_per_unit):
        k1d, k1u = u, acc(d, u)
        k2d, k2u = u + 0.5 * dt * k1u, acc(d + 0.5 * dt * k1d, u + 0.5 * dt * k1u)
        k3d, k3u = u + 0.5 * dt * k2u, acc(d + 0.5 * dt * k2d, u + 0.5 * dt * k2u)
        k4d, k4u = u + dt * k3u, acc(d + dt * k3d, u + dt * k3u)
        d1 = d + dt / 6.0 * (k1d + 2 * k2d + 2 * k3d + k4d)
        u1 = u + dt / 6.0 * (k1u + 2 * k2u + 2 * k3u + k4u)
        if d1 <= 0.0:
            s = d / (d - d1)
            return -(u + s * (u1 - u)) / v0
        f0, f1 = force(d, u), force(d1, u1)
        if f1 <= 0.0:
            s = f0 / (f0 - f1)
            return -(u + s * (u1 - u)) / v0
        d, u = d1, u1
    raise AssertionError("contact did not end")


@pytest.mark.parametrize("e", [0.2, 0.5, 0.9])
def test_dimensional_hertz_realises_requested_restitution_at_any_speed(e):
    # verification group A3 test 3: Al oxide sphere (R = 2.5 mm) on a rigid plane
    young, nu, rho, radius = 3.8e11, 0.23, 4000.0, 2.5e-3
    mass = rho * 4.0 / 3.0 * math.pi * radius**3
    k_h = hertz_stiffness(young / (1.0 - nu**2), radius)
    c_h = hertz_damping_coefficient(e)
    realised = [integrate_dimensional_hertz(mass, k_h, c_h, v) for v in (3.9, 0.39)]
    assert realised[0] == pytest.approx(e, abs=1e-5)  # A3 asks for 0.02
    assert realised[1] == pytest.approx(e, abs=1e-5)
    # the scaling argument: e depends on c_h alone (glass pair, 10 mm, 10 m/s, same c_h)
    glass_mass = 2800.0 * 4.0 / 3.0 * math.pi * 0.01**3 / 2.0
    glass_k = hertz_stiffness(1.0 / (2.0 * (1.0 - 0.2**2) / 4.8e10), 0.005)
    other = integrate_dimensional_hertz(glass_mass, glass_k, c_h, 10.0)
    assert other == pytest.approx(realised[0], abs=1e-9)
    assert realised[0] == pytest.approx(realised[1], abs=1e-9)


def test_hertz_kernel_without_jit_agrees():
    code = (
        "from sphere_cli.kernels.restitution import hertz_contact_dimensionless as f;"
        "print(repr(f(1.3, 0.05)))"
    )
    env = dict(os.environ, NUMBA_DISABLE_JIT="1", PYTHONPATH=str(ROOT))
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, cwd=ROOT, capture_output=True, text=True, check=True
    )
    pure = ast.literal_eval(out.stdout.strip())
    jitted = hertz_contact_dimensionless(1.3, 0.05)
    assert pure == pytest.approx(jitted, rel=1e-13)
