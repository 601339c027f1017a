"""sphere: discrete-element simulation of dry and fluid-saturated granular materials."""

import hashlib
import os
from pathlib import Path

import numba

from . import compile_lock

# OpenMP first: measured faster than TBB and workqueue at 2 threads (docs/performance.md).
# An explicit NUMBA_THREADING_LAYER in the environment still wins.
numba.config.THREADING_LAYER_PRIORITY = ["omp", "tbb", "workqueue"]


def _kernel_cache_dir() -> Path:
    """Numba's cache checks only the source file of each kernel, not the functions it inlines
    from other files: a cache keyed by the hash of every kernel source cannot go stale."""
    digest = hashlib.sha256()
    kernels = Path(__file__).parent / "kernels"
    for path in sorted(kernels.rglob("*.py")):
        digest.update(str(path.relative_to(kernels)).encode())
        digest.update(path.read_bytes())
    base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    return base / "sphere" / "numba" / digest.hexdigest()[:16]


def _use_kernel_cache_dir() -> None:
    path = _kernel_cache_dir()
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".probe-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError:
        return  # unwritable home: numba's own cache location (beside the package) is used
    numba.config.CACHE_DIR = str(path)


if not os.environ.get("NUMBA_CACHE_DIR"):
    _use_kernel_cache_dir()

compile_lock.install()  # processes starting together compile each kernel once (compile_lock.py)
