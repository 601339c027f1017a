"""The exact sums of kernels/exact_sum.py, which make the force on a moving wall the same on any
partition of the particles (threads, MPI ranks, GPU threads): the same double in any order of
the values, and that double the exact sum rounded (compared with math.fsum, which rounds the
exact sum correctly), across the whole range of doubles."""

from __future__ import annotations

import math

import numpy as np
import pytest
from numba import njit

from sphere_cli.kernels.exact_sum import BINS, WORDS, add_exact, exact_value


@njit(cache=True)
def _sum(values):
    words = np.zeros(WORDS, dtype=np.int64)
    for v in values:
        add_exact(words, v)
    return exact_value(words)


@njit(cache=True)
def _words(values):
    words = np.zeros(WORDS, dtype=np.int64)
    for v in values:
        add_exact(words, v)
    return words


def _spread(rng, n, low, high):
    """n doubles of random sign and significand, their exponents spread from 10^low to 10^high."""
    return rng.standard_normal(n) * 10.0 ** rng.integers(low, high, n)


CASES = {
    "unit": (0, 1),
    "16 orders": (-8, 9),
    "the whole range": (-300, 300),
    "subnormals": (-320, -308),
}


@pytest.mark.parametrize("low, high", CASES.values(), ids=CASES.keys())
def test_the_sum_is_the_exact_sum_rounded_in_any_order(low, high):
    rng = np.random.default_rng(4)
    for _ in range(200):
        values = _spread(rng, int(rng.integers(1, 300)), low, high)
        exact = math.fsum(values)
        got = _sum(values)
        assert abs(got - exact) <= math.ulp(exact)  # within one unit in the last place
        for order in (values[::-1], rng.permutation(values)):
            assert _sum(np.ascontiguousarray(order)) == got  # bitwise, whatever the order
        # split in two, each part's words added: MPI_SUM of the ranks' words
        cut = int(rng.integers(0, values.size + 1))
        words = _words(values[:cut]) + _words(values[cut:])
        assert exact_value(words) == got


def test_cancellation_and_the_edges_of_the_range():
    big = np.finfo(np.float64).max
    tiny = 5e-324  # the smallest subnormal
    assert _sum(np.array([1e300, 1.0, -1e300])) == 1.0  # a float sum in this order gives 0
    assert _sum(np.array([0.1] * 10)) == math.fsum([0.1] * 10) == 1.0  # a float sum gives 0.9999999999999999
    assert _sum(np.array([tiny, tiny, -tiny])) == tiny
    assert _sum(np.array([big, -big, big])) == big
    assert _sum(np.array([big, big])) == math.inf  # beyond the range, as a float sum
    assert _sum(np.array([-big, -big])) == -math.inf
    assert _sum(np.array([-2.5, 1.0])) == -1.5
    zero = _sum(np.array([-0.0, 0.0, 3.0, -3.0]))
    assert zero == 0.0 and math.copysign(1.0, zero) == 1.0  # a zero sum is +0.0
    assert _sum(np.zeros(0)) == 0.0


def test_a_value_that_is_not_finite_makes_the_sum_nan():
    """A NaN or infinite force must not vanish into the integers: the stability checks look for
    it in the walls' forces."""
    for bad in (math.nan, math.inf, -math.inf):
        words = _words(np.array([1.0, bad, 2.0]))
        assert words[BINS] == 1
        assert math.isnan(exact_value(words))


def test_a_word_holds_two_to_the_thirty_values_of_the_largest_parts():
    """The limit the module states: each value adds at most 2^33 to a word, so 2^30 of them stay
    below 2^63. Added as the accumulator's integers (not 2^30 calls): the same values in a word
    multiplied, then rounded."""
    value = 1.9999999999999998 * 2.0**40  # every bit of the significand set
    one = _words(np.array([value]))
    assert one[: BINS - 1].max() < 2**33
    many = one * 2**30  # the words of 2^30 such values, exact in int64
    assert many.max() < 2**63
    assert exact_value(many) == value * 2.0**30  # exact: a power of two times the value
