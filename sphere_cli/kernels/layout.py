"""Flat views of per-particle vectors, for loops the compiler can vectorise and keep in
registers.

A (N,3) array indexed a[i, axis] costs an address computation with its run-time row stride per
array, and a signed index makes Numba emit negative-index wraparound code at every access:
either keeps a loop over particles scalar, and in the contact sweeps the strides of ten arrays
spill registers. Viewed flat, a[3 i + axis] with unsigned i shares one index between all the
arrays and has a stride the compiler knows.
"""

import numpy as np
from numba import njit

U1 = np.uint64(1)
U2 = np.uint64(2)
U3 = np.uint64(3)


@njit(cache=True, inline="always")
def flat(a):
    """The (N,3) C-contiguous array a as a (3N,) view: element (i, axis) is at 3 i + axis."""
    return a.reshape(a.size)
