"""kernels/layout.py flat: the 1-D view of a C-contiguous array that the kernels index as
a[3 i + axis], made by an intrinsic (docs/architecture.md); and prefetch, the hint the pair
sweep gives for its partners' lines."""

import platform

import numba
import numpy as np
import pytest

from sphere_cli.kernels.layout import flat, prefetch


@numba.njit
def _write_through_view(a, value):
    line = flat(a)
    for m in range(line.shape[0]):
        line[m] = value * m
    return line


def test_the_flat_view_is_the_arrays_own_memory_in_c_order():
    a = np.zeros((5, 3))
    line = _write_through_view(a, 2.0)
    assert line.shape == (15,)
    assert np.shares_memory(line, a)
    assert np.array_equal(a, (2.0 * np.arange(15)).reshape(5, 3))  # element (i, axis) at 3 i + axis


def test_an_empty_array_gives_an_empty_view():
    assert _write_through_view(np.zeros((0, 3)), 1.0).shape == (0,)


def test_a_strided_array_is_refused_when_the_kernel_compiles():
    with pytest.raises(numba.core.errors.TypingError):
        _write_through_view(np.zeros((5, 6))[:, ::2], 1.0)


@numba.njit
def _sum_hinted(a, ahead):
    total = 0.0
    for m in range(a.shape[0]):
        if m + ahead < a.shape[0]:
            prefetch(a, m + ahead)
        total += a[m]
    return total


def test_a_prefetch_changes_nothing_and_is_emitted():
    a = np.random.default_rng(0).normal(size=1000)
    before = a.copy()
    assert _sum_hinted(a, 64) == _sum_hinted(a, a.shape[0])  # with hints and without, the same sum
    assert np.array_equal(a, before)
    if platform.machine() in ("x86_64", "AMD64"):
        assembly = _sum_hinted.inspect_asm(_sum_hinted.signatures[0])
        assert "prefetcht0" in assembly  # the hint reached the machine code


@numba.njit
def _hint(a, index):
    prefetch(a, index)


def test_a_prefetch_takes_a_line_of_a_1d_array_only():
    _hint(np.zeros(4), 2)
    with pytest.raises(numba.core.errors.TypingError):
        _hint(np.zeros((4, 3)), 1)
    with pytest.raises(numba.core.errors.TypingError):
        _hint(np.zeros(4), 1.0)
