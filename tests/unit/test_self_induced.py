"""The grid's response to a particle's own drag (physics/fluid/self_induced.py): its bands against
the lattice integrals evaluated here independently (full range, no symmetry, other resolutions)."""

from __future__ import annotations

import numpy as np
import pytest

from sphere_cli.physics.fluid.self_induced import lattice_modes


def _lattice(spacing, n, times=()):
    """Over [-pi, pi]^3 with n midpoints per axis, for component x: alpha [1/m], beta [-] and the
    step response sum w (1 - exp(-lambda t)) / alpha at each t [m^2/nu]."""
    theta = (np.arange(n) + 0.5) / n * 2 * np.pi - np.pi
    tx, ty, tz = np.meshgrid(theta, theta, theta, indexing="ij", sparse=True)
    s2 = [(2 * np.sin(t / 2) / h) ** 2 for t, h in zip((tx, ty, tz), spacing, strict=True)]
    lam = s2[0] + s2[1] + s2[2]
    w = np.cos(tx / 2) ** 2 * (1 - s2[0] / lam)
    volume = float(np.prod(spacing))
    alpha = (w / lam).mean() / volume
    steps = [(w * -np.expm1(-lam * t) / lam).mean() / volume / alpha for t in times]
    return alpha, w.mean(), steps


def test_steady_response_on_cubic_cells():
    """alpha dx = 0.12637 (Richardson from 64 and 128 points over the full range: the midpoint
    rule converges as 1/n), beta = 0.39508; the bands sum to both."""
    coarse, _, _ = _lattice((1.0, 1.0, 1.0), 64)
    fine, beta, _ = _lattice((1.0, 1.0, 1.0), 128)
    alpha = 2 * fine - coarse
    assert alpha == pytest.approx(0.12637, abs=2e-5)
    weight, rate = lattice_modes((1.0, 1.0, 1.0))
    assert weight.sum(axis=1) == pytest.approx([alpha] * 3, rel=1e-4)
    assert (weight * rate).sum(axis=1) == pytest.approx([beta] * 3, rel=1e-4)
    assert np.all(weight > 0) and np.all(np.diff(rate[0]) > 0)


def test_bands_scale_with_the_cell_and_follow_anisotropy():
    """W ~ 1/dx and lambda ~ 1/dx^2; on cells twice as tall the x and y responses agree and
    differ from z, each matching the full-range integral of its own component."""
    w1, r1 = lattice_modes((1.0, 1.0, 1.0))
    w2, r2 = lattice_modes((1e-3, 1e-3, 1e-3))
    assert w2 == pytest.approx(w1 * 1e3, rel=1e-12)
    assert r2 == pytest.approx(r1 * 1e6, rel=1e-12)
    weight, _ = lattice_modes((1e-3, 1e-3, 2e-3))
    assert weight[0].sum() == pytest.approx(weight[1].sum(), rel=1e-12)
    coarse, _, _ = _lattice((1e-3, 1e-3, 2e-3), 64)
    fine, _, _ = _lattice((1e-3, 1e-3, 2e-3), 128)
    assert weight[0].sum() == pytest.approx(2 * fine - coarse, rel=2e-4)
    coarse, _, _ = _lattice((2e-3, 1e-3, 1e-3), 64)  # z of the tall cells is x of these
    fine, _, _ = _lattice((2e-3, 1e-3, 1e-3), 128)
    assert weight[2].sum() == pytest.approx(2 * fine - coarse, rel=2e-4)


def test_bands_follow_the_slow_approach_of_diffusion():
    """The bands' step response against the lattice's own at t = 0.03 ... 100 dx^2/nu: within 0.015
    of alpha (six bands a factor 4 apart); the lattice reaches 0.75 of alpha at t = dx^2/nu and
    0.93 at 10, where one exponential of the same alpha and beta would be at 0.96 and 1.00."""
    times = (0.03, 0.1, 0.3, 1.0, 3.0, 10.0, 30.0, 100.0)
    _, _, lattice = _lattice((1.0, 1.0, 1.0), 128, times)
    weight, rate = lattice_modes((1.0, 1.0, 1.0))
    bands = [(weight[0] * -np.expm1(-rate[0] * t)).sum() / weight[0].sum() for t in times]
    assert np.max(np.abs(np.array(bands) - lattice)) < 0.015
    assert lattice[3] == pytest.approx(0.75, abs=0.01)
    assert lattice[5] == pytest.approx(0.93, abs=0.01)


def _kick_until_steady(coef, u_cell, spacing=1e-3, mu=1e-3, rho=1e3, steps=4000):
    """Particles held in place (1/m = 0) in one cubic cell whose fluid moves at u_cell along x,
    each with drag coefficient coef [kg/s], through drag_kick's self-induced bands for `steps`
    steps of 0.05 dx^2/nu (200 dx^2/nu in all): their drag along x and their u' (summed over
    the bands)."""
    from sphere_cli.kernels.fluid.drag import cell_coefficients, drag_kick
    from sphere_cli.physics.fluid.self_induced import MODES

    n = len(coef)
    coef = np.asarray(coef, float)
    zeros = np.zeros((n, 3))
    cell_of = np.zeros(n, dtype=np.int64)
    u = np.array([[u_cell, 0.0, 0.0]])
    weight, rate = lattice_modes((spacing,) * 3)
    nu = mu / rho
    dt = 0.05 * spacing**2 / nu
    decay = np.exp(-nu * rate * dt)
    f_drag = coef[:, None] * np.array([u_cell, 0.0, 0.0])
    disturbance = np.zeros((n, 3, MODES))
    cell_coef = np.zeros(1)
    cell_coefficients(cell_of, coef, cell_coef)
    for _ in range(steps):
        drag_kick(
            zeros.copy(), zeros.copy(), zeros, np.zeros(n), np.zeros(n), cell_of, u, coef, zeros, dt,
            zeros.copy(), f_drag, zeros.copy(), disturbance, cell_coef, spacing**3, weight, rate, decay,
            mu, nu,
        )  # fmt: skip
    return f_drag[:, 0], disturbance[:, 0].sum(axis=1)


def test_a_lone_particle_takes_back_its_own_wake_and_a_crowded_one_does_not():
    """Alone in its cell, a particle's u' reaches -alpha F/mu (to the 2 % of the band model's slow
    tail left after 200 dx^2/nu), so its drag is K u/(1 - K alpha/mu); among 63 others of the
    same K (a bed: their drag screens the cell's fluid, kappa^2 = 63 K/(mu V) = 150/dx^2, above
    every band's rate) its u' is 1.8e-4 of u (alone: 0.43 of it), and the drag K u to 2e-4. A
    particle whose loop gain K alpha/mu would exceed 1/2 (one nearly as wide as its cell) is
    capped there: its drag stays finite, at most 2 K u."""
    mu, dx, u_cell = 1e-3, 1e-3, 1e-2
    alpha = lattice_modes((dx,) * 3)[0][0].sum()
    k = 0.3 * mu / alpha  # loop gain 0.3
    drag, own = _kick_until_steady([k], u_cell, dx, mu)
    assert own[0] == pytest.approx(-alpha * drag[0] / mu, rel=0.02)
    assert drag[0] == pytest.approx(k * u_cell / (1 - 0.3), rel=0.02)
    drag, own = _kick_until_steady([k] * 64, u_cell, dx, mu)
    assert np.abs(own).max() < 5e-4 * u_cell
    assert drag == pytest.approx(k * u_cell, rel=5e-4)
    drag, own = _kick_until_steady([3.0 * mu / alpha], u_cell, dx, mu)
    assert np.isfinite(drag[0]) and drag[0] <= 2.0 * 3.0 * mu / alpha * u_cell * (1 + 1e-9)
