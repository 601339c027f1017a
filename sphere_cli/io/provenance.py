"""Where and with what a run was made: versions, threads, host, batch job, command line."""

from __future__ import annotations

import getpass
import os
import platform
import socket
import sys
from datetime import UTC, datetime
from importlib import metadata

from .. import ranks


def _version(package: str) -> str:
    try:
        return metadata.version(package)
    except metadata.PackageNotFoundError:
        return "unknown"


def _user() -> str:
    try:
        return getpass.getuser()
    except (KeyError, OSError):
        return ""


def provenance() -> dict:
    import numba

    return {
        "sphere_version": _version("sphere-cli"),
        "python": platform.python_version(),
        "numba": _version("numba"),
        "numpy": _version("numpy"),
        "h5py": _version("h5py"),
        "threads": int(numba.get_num_threads()),
        "mpi_ranks": ranks.count(),
        "threading_layer": os.environ.get("NUMBA_THREADING_LAYER", "default"),
        "host": socket.gethostname(),
        "user": _user(),
        "platform": platform.platform(),
        "job_id": os.environ.get("SLURM_JOB_ID", ""),
        "array_task_id": os.environ.get("SLURM_ARRAY_TASK_ID", ""),
        "command": " ".join(sys.argv),
        "started": datetime.now(UTC).isoformat(timespec="seconds"),
    }
