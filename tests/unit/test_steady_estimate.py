"""The steady-state estimate `sphere inspect` gives for each scalar observable
(io/inspect.py steady_estimate): the mean of the latter half with its batch-means error, and the
drift that tells a settled series from one still changing."""

from __future__ import annotations

import numpy as np
import pytest

from sphere_cli.io.inspect import STEADY_MIN_SAMPLES, steady_estimate


def test_white_noise_is_steady_and_its_error_is_the_standard_error():
    """400 samples of 2 + 0.1 N(0, 1): the mean within 3 errors of 2, the error sigma/sqrt(200)
    = 0.0071 to the accuracy of 8 batch means (a chi distribution of 7 degrees of freedom:
    within a factor 2 except for 1 seed in 10^4), no drift to speak of."""
    rng = np.random.default_rng(7)
    times = np.arange(400) * 1e-3
    e = steady_estimate(times, 2.0 + 0.1 * rng.standard_normal(400))
    assert abs(e["mean"] - 2.0) < 3 * e["error"]
    assert 0.5 * 0.1 / np.sqrt(200) < e["error"] < 2.0 * 0.1 / np.sqrt(200)
    assert abs(e["drift_sigma"]) < 4
    assert e["from_time"] == pytest.approx(0.2) and e["to_time"] == pytest.approx(0.399)


def test_a_trend_shows_as_drift():
    """A series still rising (0 to 1 over the run, noise 0.01): its trend is many errors."""
    rng = np.random.default_rng(8)
    values = np.linspace(0.0, 1.0, 400) + 0.01 * rng.standard_normal(400)
    assert steady_estimate(np.arange(400.0), values)["drift_sigma"] > 10


def test_a_constant_has_no_error_and_short_or_broken_series_none():
    e = steady_estimate(np.arange(64.0), np.full(64, 3.0))
    assert e["mean"] == 3.0 and e["error"] == 0.0 and e["drift_sigma"] == 0.0
    assert steady_estimate(np.arange(STEADY_MIN_SAMPLES - 1.0), np.ones(STEADY_MIN_SAMPLES - 1)) is None
    broken = np.ones(64)
    broken[10] = np.nan
    assert steady_estimate(np.arange(64.0), broken) is None
