"""Turbulent velocity fluctuations of the vans1d fluid (kernels/fluid/turbulent_fluctuations.py),
YADE HydroForceEngine's discrete random walk: the moments its construction gives, the eddy
lifetime, who gets none, and a sequence that depends on (seed, particle, draw) only.

Statistics: with u* = sqrt(R/rho), w' = r1 u*, v' = r2 u*, u' = (r4 - r1) u* (correlated) give
<w'^2> = <v'^2> = u*^2, <u'^2> = 2 u*^2, <u'w'> = -u*^2 = -R/rho (the Reynolds shear stress),
means 0; independent: <u'^2> = u*^2, <u'w'> = 0. Over N = 40 000 draws each sample moment has a
standard error of about sqrt(var(x y)/N) <= 0.016 u*^2; the bounds are 5 of those.
"""

from __future__ import annotations

import numba
import numpy as np
import pytest

from sphere_cli.kernels.fluid.turbulent_fluctuations import turbulent_fluctuations

RHO, NU, KAPPA, BED = 1000.0, 1.0e-6, 0.41, 0.01
FACES = np.linspace(0.0, 0.05, 51)
STRESS = 0.4  # [Pa]: u* = 0.02 m/s
U_STAR = (STRESS / RHO) ** 0.5


def draw(pos, correlated=True, seed=7, elapsed=0.0, state=None, reynolds=None):
    n = pos.shape[0]
    fluct, lifetime, draws = (
        state if state is not None else (np.zeros((n, 3)), np.zeros(n), np.zeros(n, np.uint64))
    )
    turbulent_fluctuations(
        pos, np.arange(n), np.ones(n, np.uint8), FACES, np.full(51, STRESS) if reynolds is None else reynolds,
        RHO, NU, KAPPA, BED, np.uint64(seed), correlated, elapsed, fluct, lifetime, draws,
    )  # fmt: skip
    return fluct, lifetime, draws


def above_bed(n=40_000):
    rng = np.random.default_rng(1)
    pos = np.zeros((n, 3))
    pos[:, 2] = rng.uniform(0.012, 0.045, n)
    return pos


@pytest.mark.parametrize("correlated", [True, False])
def test_moments_are_the_reynolds_stress(correlated):
    fluct, _, draws = draw(above_bed(), correlated)
    u, v, w = (fluct[:, k] / U_STAR for k in range(3))
    bound = 5 * 0.016
    for mean in (u.mean(), v.mean(), w.mean()):
        assert abs(mean) < bound
    assert np.mean(w * w) == pytest.approx(1.0, abs=bound)
    assert np.mean(v * v) == pytest.approx(1.0, abs=bound)
    assert np.mean(u * u) == pytest.approx(2.0 if correlated else 1.0, abs=2 * bound)
    assert np.mean(u * w) == pytest.approx(-1.0 if correlated else 0.0, abs=bound)
    assert np.mean(v * w) == pytest.approx(0.0, abs=bound)
    assert np.all(draws == 1)


def test_lifetime_is_the_eddy_time_above_the_bed_and_lasts():
    """0.33 kappa (z - bed) / u*, at least at the sublayer height 11.6 nu / u*; the fluctuation
    stays until its lifetime has passed, then a new one is drawn."""
    pos = np.zeros((3, 3))
    pos[:, 2] = [0.03, BED + 1e-5, 0.02]
    fluct, lifetime, draws = draw(pos)
    depth = np.array([0.02, 11.6 * NU / U_STAR, 0.01])
    np.testing.assert_allclose(lifetime, 0.33 * KAPPA * depth / U_STAR, rtol=1e-12)
    first = fluct.copy()
    state = (fluct, lifetime, draws)
    draw(pos, elapsed=0.5 * lifetime.min(), state=state)
    assert np.array_equal(fluct, first) and np.all(draws == 1)
    draw(pos, elapsed=lifetime.max(), state=state)
    assert not np.any(fluct == first) and np.all(draws == 2)


def test_none_in_the_bed_above_the_surface_or_without_reynolds_stress():
    pos = np.zeros((4, 3))
    pos[:, 2] = [0.5 * BED, BED, 0.06, 0.03]
    fluct, lifetime, draws = draw(pos)
    assert np.all(fluct[:3] == 0.0) and np.all(lifetime[:3] == 0.0) and np.all(draws[:3] == 0)
    assert np.any(fluct[3] != 0.0)
    fluct, _, draws = draw(pos, reynolds=np.zeros(51))
    assert np.all(fluct == 0.0) and np.all(draws == 0)


def test_the_sequence_depends_on_seed_particle_and_draw_only():
    """Bitwise the same on 1 and 2 threads and for the same particle among other particles; a
    different seed gives different draws."""
    pos = above_bed(1000)
    results = []
    for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
        numba.set_num_threads(threads)
        results.append(draw(pos)[0])
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    assert np.array_equal(results[0], results[1])
    alone = draw(pos[500:501])[0]
    assert not np.array_equal(alone[0], results[0][500])  # index 0 of its own array: another stream
    again = draw(pos[:501])[0]
    assert np.array_equal(again[500], results[0][500])
    assert not np.any(draw(pos, seed=8)[0] == results[0])
