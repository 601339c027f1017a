"""Shared fixtures: small cases written as TOML text, run through the library API."""

from __future__ import annotations

import os
import textwrap
from pathlib import Path

import pytest

# The GPU kernels run under Numba's CUDA simulator unless asked otherwise (NUMBA_ENABLE_CUDASIM=0
# on a GPU machine): set before Numba reads its configuration, also for the processes tests start.
os.environ.setdefault("NUMBA_ENABLE_CUDASIM", "1")


@pytest.fixture
def write_case(tmp_path: Path):
    """Write dedented TOML text to a file in tmp_path and return its path."""

    def _write(text: str, name: str = "case.toml") -> Path:
        path = tmp_path / name
        path.write_text(textwrap.dedent(text))
        return path

    return _write
