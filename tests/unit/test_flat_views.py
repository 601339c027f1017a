"""kernels/layout.py flat: the 1-D view of a C-contiguous array that the kernels index as
a[3 i + axis], made by an intrinsic (docs/architecture.md)."""

import numba
import numpy as np
import pytest

from sphere_cli.kernels.layout import flat


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
