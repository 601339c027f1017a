"""Fixtures of the verification tests."""

from __future__ import annotations

import numba
import pytest


@pytest.fixture(autouse=True)
def single_numba_thread():
    """One Numba thread, as `sphere verify` uses: the scenes hold 1-6 particles, for which a
    parallel region costs more than it saves (results do not depend on the thread count)."""
    previous = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        yield
    finally:
        numba.set_num_threads(previous)
