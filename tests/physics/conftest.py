"""Fixtures shared by the physics (verification) tests."""

from __future__ import annotations

import numba
import pytest


@pytest.fixture(autouse=True)
def single_numba_thread():
    """Run each physics test on one Numba thread, then restore the previous count.

    The scenes here hold 1-300 particles, for which the fork-join cost of a parallel region
    (four per step) outweighs the work, and is much worse on a loaded machine. Results do not
    depend on the thread count: test_dem_thread_independence.py checks that bitwise.
    """
    previous = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(previous)
