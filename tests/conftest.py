"""Shared fixtures: small cases written as TOML text, run through the library API."""

from __future__ import annotations

import os
import textwrap
import time
from pathlib import Path

import pytest

# The GPU kernels run under Numba's CUDA simulator unless asked otherwise (NUMBA_ENABLE_CUDASIM=0
# on a GPU machine): set before Numba reads its configuration, also for the processes tests start.
os.environ.setdefault("NUMBA_ENABLE_CUDASIM", "1")


def _let_simulated_gpu_threads_run() -> None:
    """The simulator runs a launch's CUDA threads as Python threads while the launching thread
    polls them in a loop that never waits (its BlockManager.run asks each BlockThread is_alive):
    it holds the interpreter half the time and a core all the time. A zero sleep in that poll
    hands the interpreter to the kernel's thread: the two simulator files ran in 56 s instead of
    108 s beside a busy core. A test fails at once if a Numba release renames what is patched."""
    from numba import config

    if not config.ENABLE_CUDASIM:
        return
    from numba.cuda.simulator import kernel

    polled = kernel.BlockThread.is_alive

    def is_alive(thread) -> bool:
        time.sleep(0)
        return polled(thread)

    kernel.BlockThread.is_alive = is_alive


_let_simulated_gpu_threads_run()

# The files that take a worker longest (seconds of a warm run on the 2-core machine, 2026-12-07),
# run first: `make test` hands whole files to its two workers in the order collected, so a long
# file collected last ran while the other worker had nothing left (the suite is at its 10-minute
# budget). The other files keep their order, after these.
LONGEST_FIRST = (
    "tests/cli/test_ranks.py",  # 200 s
    "tests/unit/test_compiled_steps.py",  # 80
    "tests/unit/test_cuda_fluids.py",  # 75
    "tests/unit/test_cuda_dem.py",  # 63
    "tests/verify/test_verify_quick.py",  # 48
    "tests/restart/test_nothing_lost.py",  # 44
    "tests/unit/test_compile_ahead.py",  # 38
    "tests/cli/test_sweep.py",  # 34
)


def pytest_collection_modifyitems(config, items) -> None:
    root = Path(config.rootpath)

    def rank(item) -> int:
        name = Path(item.fspath).relative_to(root).as_posix()
        return LONGEST_FIRST.index(name) if name in LONGEST_FIRST else len(LONGEST_FIRST)

    items.sort(key=rank)  # stable: each file's tests, and the other files, keep their order


@pytest.fixture
def write_case(tmp_path: Path):
    """Write dedented TOML text to a file in tmp_path and return its path."""

    def _write(text: str, name: str = "case.toml") -> Path:
        path = tmp_path / name
        path.write_text(textwrap.dedent(text))
        return path

    return _write
