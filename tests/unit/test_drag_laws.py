"""Drag laws of kernels/fluid/drag.py: limits, branch switches, dimensions (verification group D, E).

References: Ergun (1952) and Wen & Yu (1966) in the form of Gidaspow (1994, "Multiphase flow and
fluidization", eqs. 9.4-9.5): beta = 150 mu (1-phi)^2/(phi d^2) + 1.75 rho (1-phi) w/d for
phi <= 0.8, beta = 3/4 C_d phi (1-phi) rho w phi^-2.65/d above, Re = phi rho d w/mu,
C_d = 24/Re (1 + 0.15 Re^0.687) below Re = 1000, 0.44 above (Schiller & Naumann 1933);
Di Felice (1994), Int. J. Multiphase Flow 20:153, C_d = (0.63 + 4.8/sqrt(Re))^2.
"""

from __future__ import annotations

import ast
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sphere_cli.kernels.fluid.drag import DI_FELICE, GIDASPOW, drag_rate, phi1

ROOT = Path(__file__).resolve().parents[2]
MU, RHO, D = 1.41, 1260.0, 2.0e-3  # glycerol, 2 mm sphere
FLOOR = 0.1
LAWS = (GIDASPOW, DI_FELICE)


def force_coefficient(law, phi, w, d=D, rho=RHO, mu=MU):
    """K [kg/s]: drag on one sphere = K (u - v)."""
    return math.pi / 6.0 * d**3 * drag_rate(law, phi, d, w, rho, mu, FLOOR)


def test_isolated_sphere_limit_is_stokes_and_schiller_naumann():
    """phi -> 1: Wen-Yu becomes the drag of an isolated sphere, 3 pi mu d (1 + 0.15 Re^0.687)
    (to round-off); Di Felice's C_d tends to 23.04/Re, 0.96 of Stokes."""
    for w in (0.0, 1e-3, 0.05):
        re = RHO * D * w / MU
        stokes = 3.0 * math.pi * MU * D
        assert force_coefficient(GIDASPOW, 1.0, w) == pytest.approx(
            stokes * (1 + 0.15 * re**0.687), rel=1e-13
        )
    assert force_coefficient(DI_FELICE, 1.0, 0.0) == pytest.approx(0.96 * 3.0 * math.pi * MU * D, rel=1e-13)


def test_terminal_velocity_of_the_steel_sphere_in_glycerol():
    """D: steel d = 2 mm (7800 kg/m^3) in glycerol (1260, 1.41 Pa s): v_t = 0.010017 m/s with
    Schiller-Naumann (0.010111 m/s Stokes). Fixed point of K(v) v = (rho_p - rho_f) g V."""
    weight = (7800.0 - RHO) * 9.81 * math.pi / 6.0 * D**3
    v = 0.0
    for _ in range(60):
        v = weight / force_coefficient(GIDASPOW, 1.0, v)
    assert v == pytest.approx(0.010017, abs=0.5e-6)
    assert weight / force_coefficient(GIDASPOW, 1.0, 0.0) == pytest.approx(0.010111, abs=0.5e-6)


def test_schiller_naumann_branch_at_re_1000_is_continuous_to_its_own_jump():
    """C_d at Re = 1000: 24/1000 (1 + 0.15 1000^0.687) = 0.4387 against 0.44 above: the
    correlation's own 0.3 % step, no more."""
    phi = 0.9
    w = 1000.0 * MU / (phi * RHO * D)
    below = force_coefficient(GIDASPOW, phi, w * (1 - 1e-12))
    above = force_coefficient(GIDASPOW, phi, w)
    expected = 0.44 / (24.0 / 1000.0 * (1.0 + 0.15 * 1000.0**0.687))
    assert above / below == pytest.approx(expected, rel=1e-9)
    assert abs(above / below - 1.0) < 0.004


@pytest.mark.parametrize("w", [0.0, 1e-4, 0.01, 1.0])
def test_gidaspow_switch_at_porosity_0_8(w):
    """At phi = 0.8 the Ergun branch applies (phi <= 0.8), just above it Wen-Yu, each equal to
    its formula; the switch is as discontinuous as the formulas make it: at Re -> 0 the ratio
    is (150 * 0.2/0.8)/(18 * 0.8^-2.65) = 1.153. Either side of the switch the drag is continuous
    in phi."""
    ergun = 150.0 * MU * 0.2 / (0.8 * D * D) + 1.75 * RHO * w / D
    assert drag_rate(GIDASPOW, 0.8, D, w, RHO, MU, FLOOR) == pytest.approx(ergun, rel=1e-13)
    phi = 0.8 + 1e-12
    re = phi * RHO * D * w / MU
    cd_w = 24.0 * MU / (phi * RHO * D) * (1.0 + 0.15 * re**0.687)
    wen_yu = 0.75 * cd_w * RHO * phi**-1.65 / D
    assert drag_rate(GIDASPOW, phi, D, w, RHO, MU, FLOOR) == pytest.approx(wen_yu, rel=1e-13)
    for side in (0.8 - 1e-9, 0.8 + 2e-9):
        near = 0.8 if side < 0.8 else phi
        assert drag_rate(GIDASPOW, side, D, w, RHO, MU, FLOOR) == pytest.approx(
            drag_rate(GIDASPOW, near, D, w, RHO, MU, FLOOR), rel=1e-7
        )
    if w == 0.0:
        assert ergun / wen_yu == pytest.approx(37.5 / (18.0 * 0.8**-2.65), rel=1e-9)
        assert ergun / wen_yu == pytest.approx(1.153, abs=5e-4)


@pytest.mark.parametrize("law", LAWS)
def test_finite_as_porosity_goes_to_0_and_1(law):
    """E: porosity -> 0 gives the drag at the floor (finite), phi at or a rounding above 1 the
    isolated sphere's; never NaN or inf, for any relative speed including 0."""
    for w in (0.0, 1e-6, 0.3, 50.0):
        at_floor = drag_rate(law, FLOOR, D, w, RHO, MU, FLOOR)
        for phi in (0.0, 1e-300, -1e-3, FLOOR / 2):
            assert drag_rate(law, phi, D, w, RHO, MU, FLOOR) == at_floor
        assert math.isfinite(at_floor) and at_floor > 0.0
        isolated = drag_rate(law, 1.0, D, w, RHO, MU, FLOOR)
        assert math.isfinite(isolated) and isolated > 0.0
        assert drag_rate(law, 1.0 + 1e-15, D, w, RHO, MU, FLOOR) == isolated
        assert drag_rate(law, 1.0 - 1e-12, D, w, RHO, MU, FLOOR) == pytest.approx(isolated, rel=1e-9)


@pytest.mark.parametrize("law", LAWS)
@pytest.mark.parametrize("phi", [0.4, 0.8, 0.85, 0.999])
def test_dimensionally_consistent(law, phi):
    """Scaling rho and mu by the same factor a keeps Re and the kinematic viscosity, so a
    consistent k [kg/(m^3 s)] scales by a exactly; the documentation's Wen-Yu line (an extra
    mu_f) would scale by a^2. Scaling lengths by s and speeds by 1/s keeps Re: k scales by s^-2."""
    w = 0.02
    k = drag_rate(law, phi, D, w, RHO, MU, FLOOR)
    assert drag_rate(law, phi, D, w, 3.0 * RHO, 3.0 * MU, FLOOR) == pytest.approx(3.0 * k, rel=1e-12)
    assert drag_rate(law, phi, 4.0 * D, w / 4.0, RHO, MU, FLOOR) == pytest.approx(k / 16.0, rel=1e-12)


@pytest.mark.parametrize("phi", [0.36, 0.45, 0.8])
@pytest.mark.parametrize("superficial", [1e-4, 0.05])
def test_ergun_pressure_gradient_of_a_fixed_bed(phi, superficial):
    """D: a fixed bed at porosity eps with superficial velocity U (interstitial U/eps): the drag
    per bed volume (1 - eps) k (U/eps), divided by eps (the fluid's -eps grad p carries it, model
    A), is Ergun's dP/L = 150 mu (1-eps)^2 U/(eps^3 d^2) + 1.75 rho (1-eps) U^2/(eps^3 d)."""
    u = superficial / phi
    drag_density = (1.0 - phi) * drag_rate(GIDASPOW, phi, D, u, RHO, MU, FLOOR) * u
    ergun = 150.0 * MU * (1 - phi) ** 2 * superficial / (phi**3 * D**2) + 1.75 * RHO * (
        1 - phi
    ) * superficial**2 / (phi**3 * D)
    assert drag_density / phi == pytest.approx(ergun, rel=1e-13)


def test_phi1():
    """(1 - e^-x)/x: 1 at 0, smooth through the series switch, 1/x for large x."""
    assert phi1(0.0) == 1.0
    for x in (1e-13, 1e-12, 1e-11, 1e-6, 0.5, 3.0):
        assert phi1(x) == pytest.approx(-math.expm1(-x) / x, rel=1e-14)
    assert phi1(1e6) == pytest.approx(1e-6, rel=1e-14)


def test_drag_rate_without_jit_agrees():
    """The kernel run as plain Python (NUMBA_DISABLE_JIT=1) gives the compiled values."""
    cases = [(law, phi, w) for law in LAWS for phi in (0.05, 0.5, 0.9, 1.0) for w in (0.0, 0.01, 30.0)]
    code = (
        "from sphere_cli.kernels.fluid.drag import drag_rate;"
        f"print(repr([drag_rate(l, p, {D!r}, w, {RHO!r}, {MU!r}, {FLOOR!r}) for l, p, w in {cases!r}]))"
    )
    env = dict(os.environ, NUMBA_DISABLE_JIT="1", PYTHONPATH=str(ROOT))
    out = subprocess.run(
        [sys.executable, "-c", code], env=env, cwd=ROOT, capture_output=True, text=True, check=True
    )
    pure = ast.literal_eval(out.stdout.strip())
    jitted = [drag_rate(law, phi, D, w, RHO, MU, FLOOR) for law, phi, w in cases]
    np.testing.assert_allclose(pure, jitted, rtol=1e-13)


@pytest.mark.parametrize("phi", [0.45, 0.8, 0.95])
@pytest.mark.parametrize("w", [1e-3, 0.05, 2.0])
def test_di_felice_force(phi, w):
    """Di Felice (1994): F = 1/2 C_d rho (pi d^2/4) phi^2 |w| w phi^-chi with C_d = (0.63 +
    4.8/sqrt(Re))^2, Re = phi rho d |w|/mu, chi = 3.7 - 0.65 exp(-(1.5 - log10 Re)^2/2), written
    out here from the paper's form (the kernel forms C_d |w| without dividing by |w|)."""
    re = phi * RHO * D * w / MU
    cd = (0.63 + 4.8 / math.sqrt(re)) ** 2
    chi = 3.7 - 0.65 * math.exp(-((1.5 - math.log10(re)) ** 2) / 2)
    force = 0.5 * cd * RHO * math.pi * D**2 / 4 * phi**2 * w * w * phi**-chi
    assert force_coefficient(DI_FELICE, phi, w) * w == pytest.approx(force, rel=1e-12)
