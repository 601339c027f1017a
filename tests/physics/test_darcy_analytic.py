"""The Darcy pore-pressure equation alone (no particles) against analytic solutions
(verification group C; darcy_reference.py cites each solution).

Measured (1 Numba thread): steady seepage flux and the two-layer series flux to ~1e-12
relative; spatial order of the steady variable-permeability profile 1.93, 1.97 (32 -> 64 -> 128
cells); Terzaghi with 50 cells and dt = 10x the explicit limit: max |p - p_exact| = 2.8e-3 p0;
with 100 cells and dt = 100x the explicit limit: 6.7e-3 p0 (backward Euler's O(dt) error at the
earliest time, T = 0.1); periodic top pressure: amplitudes to 0.3 % of A, lags to 0.024 rad at
three skin depths, the dispersion backward Euler predicts (see the test).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sphere_cli.verify.darcy_reference import (
    COMPRESSIBILITY,
    POROSITY,
    VISCOSITY,
    column,
    periodic_top_pressure,
    terzaghi_consolidation,
    terzaghi_pressure,
)

RHO_F = 1000.0
G_Z = -9.81
LONG = 1.0e6  # a step this long [s] reaches the steady state in one backward-Euler step


def total_to_excess(total: float, z: float, top: float) -> float:
    """Excess pressure of a total pressure at height z: the hydrostatic part rho_f |g| (top - z)
    below the top face is taken out (the model's convention, config/fluid_darcy.py)."""
    return total - RHO_F * (-G_Z) * (top - z)


def test_steady_seepage_flux_matches_darcy():
    """Upward seepage through a uniform Kozeny-Carman column: q = -(k/mu)(dP/L - rho_f g_z) with
    total pressures P at the faces and k = k_c phi^3/(1-phi)^2, to 1e-6 in every cell."""
    H, kc = 0.2, 1.0e-9
    p_bottom_total, p_top_total = 2.5e3 + RHO_F * 9.81 * H, 0.0  # 2.5 kPa above hydrostatic
    model = column(
        20,
        H,
        {
            "permeability": {"coefficient": kc},
            "top": {"pressure": total_to_excess(p_top_total, H, H)},
            "bottom": {"pressure": total_to_excess(p_bottom_total, 0.0, H)},
        },
        cells_xy=(2, 2),
        periodic_xy=(True, False),
    )
    model.advance(LONG, LONG)
    k = kc * POROSITY**3 / (1 - POROSITY) ** 2
    q_exact = -(k / VISCOSITY) * ((p_top_total - p_bottom_total) / H - RHO_F * G_Z)
    q = POROSITY * model.state.velocity  # Darcy flux = porosity x Darcy velocity
    assert q_exact > 0
    assert np.max(np.abs(q[..., 2] - q_exact)) <= 1e-6 * abs(q_exact)
    assert np.max(np.abs(q[..., :2])) <= 1e-6 * abs(q_exact)


def test_two_layers_in_series_give_the_harmonic_mean():
    """Two layers of porosity 0.3 and 0.5 (k1, k2 by Kozeny-Carman), equal thickness: the flux
    is that of the harmonic-mean permeability 2 k1 k2 / (k1 + k2), to 1e-6, in every cell (the
    Darcy velocity is made from the face fluxes, continuous across the interface); the
    pressure is linear in each layer with the interface value of the series resistances."""
    H, kc, dp, nz = 0.1, 1.0e-9, 1.0e3, 20
    model = column(
        nz, H, {"permeability": {"coefficient": kc}, "top": {"pressure": 0.0}, "bottom": {"pressure": dp}}
    )
    phi = np.where(np.arange(nz) < nz // 2, 0.3, 0.5)
    model.state.porosity[0, 0, :] = phi
    model.advance(LONG, LONG)
    k1, k2 = (kc * f**3 / (1 - f) ** 2 for f in (0.3, 0.5))
    q_exact = dp / H * (2 * k1 * k2 / (k1 + k2)) / VISCOSITY
    q = (model.state.porosity_used * model.state.velocity[..., 2])[0, 0]
    assert np.max(np.abs(q - q_exact)) <= 1e-6 * q_exact  # the cells at the interface included
    interface = dp * (0.5 * H / k2) / (0.5 * H / k1 + 0.5 * H / k2)
    z = model.grid.centres(2)
    exact = np.where(z < H / 2, dp - (dp - interface) * z / (H / 2), interface * (H - z) / (H / 2))
    assert np.max(np.abs(model.state.pressure[0, 0] - exact)) <= 1e-6 * dp


def test_spatial_order_two_with_varying_permeability():
    """Steady seepage through phi(z) = 0.35 + 0.15 sin(pi z / H) (Kozeny-Carman k(z)), bottom
    held at p_b, top at 0: p = p_b (1 - R(z)/R(H)), R(z) = int_0^z dz'/k(z'). The cell-centred
    scheme with harmonic faces is a trapezoidal rule for R (midpoint in the boundary half
    cells), so the error falls as h^2: the observed order between 64 and 128 cells must be
    2 +- 0.1 (measured 1.87, 1.93, 1.97 from 16 to 128 cells: pre-asymptotic below)."""
    H, kc, dp = 0.1, 1.0e-9, 1.0e3
    fine = np.linspace(0.0, H, 200001)
    resistance = 1.0 / (kc * (phi := 0.35 + 0.15 * np.sin(np.pi * fine / H)) ** 3 / (1 - phi) ** 2)
    R = np.concatenate([[0.0], np.cumsum(0.5 * (resistance[1:] + resistance[:-1]) * np.diff(fine))])
    errors = []
    for nz in (32, 64, 128):
        model = column(
            nz, H, {"permeability": {"coefficient": kc}, "top": {"pressure": 0.0}, "bottom": {"pressure": dp}}
        )
        z = model.grid.centres(2)
        model.state.porosity[0, 0, :] = 0.35 + 0.15 * np.sin(np.pi * z / H)
        model.advance(LONG, LONG)
        exact = dp * (1.0 - np.interp(z, fine, R) / R[-1])
        errors.append(np.max(np.abs(model.state.pressure[0, 0] - exact)) / dp)
    orders = [math.log2(errors[i] / errors[i + 1]) for i in range(2)]
    print(f"steady variable k: max errors {errors}, observed orders {orders}")
    assert errors[-1] < 2e-4
    assert abs(orders[-1] - 2.0) < 0.1


def terzaghi_run(nz: int, dt_factor: float, times=(0.1, 0.2, 0.5, 1.0)):
    H, p0 = 1.0, 1.0e4
    model = column(
        nz,
        H,
        {
            "permeability": {"model": "constant", "value": 1e-12},
            "initial_pressure": p0,
            "bottom": {"type": "no-flow"},
        },
    )
    D = 1e-12 / (COMPRESSIBILITY * POROSITY * VISCOSITY)
    limit = model.explicit_limit()
    assert limit == pytest.approx((H / nz) ** 2 / (2 * D), rel=1e-12)  # the 1D column's limit
    dt = dt_factor * limit
    depth = H - model.grid.centres(2)
    step, results = 0, []
    for T in times:
        end = round(T * H * H / D / dt)
        while step < end:
            step += 1
            model.advance(dt, step * dt)
        T_reached = step * dt * D / H**2
        assert T_reached == pytest.approx(T, rel=1e-9)
        p = model.state.pressure[0, 0]
        error = np.max(np.abs(p - terzaghi_pressure(depth, T, p0, H))) / p0
        consolidation = 1.0 - p.mean() / p0
        results.append((T, error, consolidation))
    return results


def test_terzaghi_series_reproduces_the_published_table():
    """The reference itself: U(T) of the series against section C's table (4 digits) and
    T50, T90."""
    for T, U in ((0.1, 0.3568), (0.2, 0.5041), (0.5, 0.7640), (1.0, 0.9313)):
        assert terzaghi_consolidation(T) == pytest.approx(U, abs=6e-5)
    assert terzaghi_consolidation(0.1967) == pytest.approx(0.5, abs=1e-4)
    assert terzaghi_consolidation(0.8481) == pytest.approx(0.9, abs=1e-4)


def test_terzaghi_consolidation_50_cells():
    """50 cells, dt = 10x the explicit diffusion limit: p within 1 % of p0 everywhere and the
    average consolidation U within 0.01 of the table at T = 0.1, 0.2, 0.5, 1."""
    for T, error, U in terzaghi_run(50, 10.0):
        exact = terzaghi_consolidation(T)
        print(f"T = {T}: max |p - exact| / p0 = {error:.2e}, U = {U:.4f} (exact {exact:.4f})")
        assert error < 0.01
        assert abs(U - terzaghi_consolidation(T)) < 0.01


def test_dt_100x_the_explicit_limit_stays_accurate():
    """100 cells, dt = 100x the explicit limit h^2/(2D): still within 1 % of p0 at every T
    (backward Euler: L-stable, so no ringing; its O(dt) error is largest at T = 0.1, 20 steps
    in)."""
    for T, error, U in terzaghi_run(100, 100.0):
        print(f"T = {T}: max |p - exact| / p0 = {error:.2e}, U = {U:.4f}")
        assert error < 0.01
        assert abs(U - terzaghi_consolidation(T)) < 0.01


def test_sinusoidal_top_pressure_decays_and_lags_with_depth():
    """Top pressure A sin(omega t) over a layer 6 skin depths deep, 20 cells per skin depth,
    200 steps per period (dt = 12.6x the explicit limit), started from the periodic state and
    run two periods; amplitude and phase at each depth fitted over the second period.
    Backward Euler replaces i omega by (1 - exp(-i omega dt))/dt ~ i omega (1 - i omega dt/2),
    which changes lambda by a factor 1 - i omega dt/4: the phase at depth d is off by about
    (omega dt / 4) d / delta = 0.024 rad at d = 3 delta, the log-amplitude by as much. Bounds:
    amplitude within 0.5 % of A everywhere, lag within (omega dt/4)(d/delta) + 0.005 rad
    (spatial and fitting error) down to 3 skin depths, against both the finite layer and the
    half-space exp(-d/delta), lag d/delta."""
    k, A, period, steps = 1.0e-12, 1.0e4, 1.0, 200
    omega = 2 * math.pi / period
    D = k / (COMPRESSIBILITY * POROSITY * VISCOSITY)
    delta = math.sqrt(2 * D / omega)
    H = 6 * delta
    model = column(
        120,
        H,
        {
            "permeability": {"model": "constant", "value": k},
            "top": {"amplitude": A, "period": period},
            "bottom": {"type": "no-flow"},
        },
    )
    z = model.grid.centres(2)
    amplitude = periodic_top_pressure(z, H, A, delta)
    model.state.pressure[0, 0] = amplitude.imag  # the periodic state at t = 0
    dt = period / steps
    assert dt > 10 * model.explicit_limit()
    times, samples = [], []
    for step in range(1, 2 * steps + 1):
        model.advance(dt, step * dt)
        if step > steps:
            times.append(step * dt)
            samples.append(model.state.pressure[0, 0].copy())
    t = np.array(times)
    basis = np.stack([np.sin(omega * t), np.cos(omega * t), np.ones_like(t)], axis=1)
    (s, c, _), *_ = np.linalg.lstsq(basis, np.array(samples), rcond=None)
    fitted_amplitude = np.hypot(s, c)
    fitted_lag = -np.arctan2(c, s)
    depth = H - z
    shallow = depth <= 3 * delta
    lag_bound = omega * dt / 4 * depth[shallow] / delta + 0.005
    assert np.max(np.abs(fitted_amplitude - np.abs(amplitude))) < 0.005 * A
    assert np.all(np.abs(fitted_lag[shallow] + np.angle(amplitude[shallow])) < lag_bound)
    assert np.max(np.abs(fitted_amplitude - A * np.exp(-depth / delta))[shallow]) < 0.005 * A
    assert np.all(np.abs(fitted_lag[shallow] - depth[shallow] / delta) < lag_bound)


def test_fixed_pressure_cells_hold_their_value():
    """A region of cells held at P in the middle of a column drained at both ends (x periodic):
    the steady profile is the exact tent p = P (distance to the drained face)/(distance of the
    region's edge), and the fixed cells hold P exactly."""
    H, nz, P = 0.1, 20, 5.0e3
    h = H / nz
    model = column(
        nz,
        H,
        {
            "permeability": {"model": "constant", "value": 1e-12},
            "bottom": {"pressure": 0.0},
            "fixed_pressure": [{"lower": [0.0, 0.0, 9 * h], "upper": [2 * h, h, 11 * h], "pressure": P}],
        },
        cells_xy=(2, 1),
        periodic_xy=(True, False),
    )
    model.advance(LONG, LONG)
    z = model.grid.centres(2)
    p = model.state.pressure
    held = (z > 9 * h) & (z < 11 * h)
    assert np.all(p[:, :, held] == P)
    below = z < 9 * h
    above = z > 11 * h
    assert np.max(np.abs(p[:, 0, below] - P * z[below] / (9.5 * h))) < 1e-9 * P
    assert np.max(np.abs(p[:, 0, above] - P * (H - z[above]) / (H - 10.5 * h))) < 1e-9 * P
