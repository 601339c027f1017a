"""Sums of doubles that are exact, so the same in any order: a fixed-point accumulator.

A finite double is m 2^q with |m| < 2^53 and -1074 <= q <= 971: bits 0 to 2097 of an integer
counted from 2^-1074. The accumulator keeps that integer in BINS signed 64-bit words of 32 bits
each (word k weighs 2^(32 k - 1074)); a value is added as three parts of at most 33 bits to three
words, without rounding. Integer addition is associative, so a sum taken by one thread in index
order, by several threads, by MPI ranks (MPI_SUM of the words as int64) or by GPU threads
(integer atomics) is the same integer, and exact_value rounds it once: the wall force of
kernels/walls.py is bitwise the same on any partition of the particles, and sending the words
(BINS + 1 int64 a sum) costs the same for ten particles as for ten million.

Limits: 2^30 values a sum (a word takes 2^30 parts of 33 bits before it could overflow its 63);
a value that is not finite is counted in the last word (BINS), and the sum is then NaN.
"""

import math

import numpy as np
from numba import njit

BIN_BITS = 32
LOW_BITS = np.int64((1 << BIN_BITS) - 1)
LOWEST = 1074  # 2^-1074, the smallest subnormal, is bit 0
# the largest value's bits end at 2097; carries from 2^30 values, at 2127: 67 words, one more
# for the sign
BINS = 68
WORDS = BINS + 1  # the last counts the values that were not finite
TWO_53 = 9007199254740992.0
TWO_32 = 4294967296.0


@njit(cache=True, inline="always")
def exact_parts(value):
    """(k, a, b, c): value (finite, not zero) is a 2^(32 k - 1074) + b 2^(32 (k + 1) - 1074)
    + c 2^(32 (k + 2) - 1074), with |a| < 2^32, |b| < 2^33, |c| < 2^21 of value's sign."""
    fraction, exponent = math.frexp(abs(value))  # |value| = fraction 2^exponent, 1/2 <= fraction < 1
    m = np.int64(fraction * TWO_53)  # exact: the 53 bits of the significand
    q = exponent - 53
    if q < -LOWEST:  # a subnormal: the bits shifted out are zero
        m >>= -LOWEST - q
        q = -LOWEST
    bit = q + LOWEST
    k = bit >> 5
    shift = bit & 31
    low = (m & LOW_BITS) << shift  # < 2^63
    high = (m >> BIN_BITS) << shift  # < 2^52
    a, b, c = low & LOW_BITS, (low >> BIN_BITS) + (high & LOW_BITS), high >> BIN_BITS
    if value < 0.0:
        return k, -a, -b, -c
    return k, a, b, c


@njit(cache=True, inline="always")
def add_exact(words, value):
    """words (WORDS,) int64 += value, exactly (nothing for zero)."""
    if value == 0.0:
        return
    if not math.isfinite(value):
        words[BINS] += 1
        return
    k, a, b, c = exact_parts(value)
    words[k] += a
    words[k + 1] += b
    words[k + 2] += c


@njit(cache=True, inline="always")
def _carry(words):
    """Each word but the top into [0, 2^32), its excess carried up (an arithmetic shift floors)."""
    for k in range(BINS - 1):
        carry = words[k] >> BIN_BITS
        words[k] -= carry << BIN_BITS
        words[k + 1] += carry


@njit(cache=True, inline="always")
def exact_value(words):
    """The sum the words hold, rounded to a double (within one unit in the last place, and the
    same double for the same sum); NaN if a value was not finite. Normalises words in place."""
    if words[BINS] != 0:
        return math.nan
    _carry(words)
    sign = 1.0
    if words[BINS - 1] < 0:  # negative: take the magnitude's words
        for k in range(BINS):
            words[k] = -words[k]
        _carry(words)
        sign = -1.0
    top = BINS - 1
    while top >= 0 and words[top] == 0:
        top -= 1
    if top < 0:
        return 0.0
    bottom = max(top - 2, 0)  # the three leading words hold the significand and more
    x = 0.0
    for k in range(top, bottom - 1, -1):
        x = x * TWO_32 + float(words[k])
    return sign * math.ldexp(x, BIN_BITS * bottom - LOWEST)
