"""sphere: discrete-element simulation of dry and fluid-saturated granular materials."""

import hashlib
import os
import stat
import sys
import tempfile
from pathlib import Path


def _refuse_bad_thread_count() -> None:
    """NUMBA_NUM_THREADS=0 (a batch script's arithmetic, an empty allocation) makes `import
    numba` itself fail with a traceback, so no command could say what is wrong: said here, before
    Numba is imported, with exit 2 (a setting of the command's environment, like a bad option).
    A value that is no number Numba ignores with a warning and uses every core."""
    value = os.environ.get("NUMBA_NUM_THREADS", "").strip()
    if value and value.lstrip("+-").isdigit() and int(value) < 1:
        print(
            f"sphere: error: NUMBA_NUM_THREADS = {value!r}: expected a whole number of threads of at "
            "least 1; unset it to use every core this process may run on",
            file=sys.stderr,
        )
        raise SystemExit(2)


_refuse_bad_thread_count()

import numba  # noqa: E402  (after the check above: with NUMBA_NUM_THREADS=0 it fails to import)

from . import compile_lock  # noqa: E402

# OpenMP first: measured faster than TBB and workqueue at 2 threads (docs/performance.md).
# An explicit NUMBA_THREADING_LAYER in the environment still wins.
numba.config.THREADING_LAYER_PRIORITY = ["omp", "tbb", "workqueue"]


def _kernel_sources_digest() -> str:
    """Numba's cache checks only the source file of each kernel, not the functions it inlines
    from other files: a cache keyed by the hash of every kernel source cannot go stale."""
    digest = hashlib.sha256()
    kernels = Path(__file__).parent / "kernels"
    for path in sorted(kernels.rglob("*.py")):
        digest.update(str(path.relative_to(kernels)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _kernel_cache_dirs() -> list[Path]:
    """Where the compiled kernels may be cached, in order: the user's cache directory, then one
    of this user's own in the temporary directory (a read-only home, as in some containers and
    on some clusters' compute nodes; Numba's own place beside the package is often read-only
    too, and without a writable place every command would fail at import)."""
    digest = _kernel_sources_digest()
    base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    if not hasattr(os, "getuid"):  # (not POSIX)
        return [base / "sphere" / "numba" / digest]
    own = Path(tempfile.gettempdir()) / f"sphere-{os.getuid()}"
    return [base / "sphere" / "numba" / digest, own / "numba" / digest]


def _writable(path: Path, owned_below: Path | None = None) -> bool:
    """Whether `path` can be made and written; with `owned_below` (a folder in a directory other
    users share), only if that folder is this user's alone: no one else may plant kernels, which
    Numba loads as pickles."""
    try:
        if owned_below is not None:
            owned_below.mkdir(mode=0o700, exist_ok=True)
            held = owned_below.lstat()  # (a link is not followed)
            if not stat.S_ISDIR(held.st_mode) or held.st_uid != os.getuid() or held.st_mode & 0o022:
                return False
        path.mkdir(mode=0o700, parents=True, exist_ok=True)
        probe = path / f".probe-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError:
        return False
    return True


# said in each run's log where the kernels are cached when it is not the user's cache directory
KERNEL_CACHE_NOTE: str | None = None


def _use_kernel_cache_dir() -> None:
    global KERNEL_CACHE_NOTE
    preferred, *others = _kernel_cache_dirs()
    for path in (preferred, *others):
        if _writable(path, None if path == preferred else path.parent.parent):
            numba.config.CACHE_DIR = str(path)
            if path != preferred:
                KERNEL_CACHE_NOTE = (
                    f"{preferred.parents[2]} cannot be written: the compiled kernels are cached in "
                    f"{path}, which may not last; set NUMBA_CACHE_DIR to a directory that does"
                )
            return


if not os.environ.get("NUMBA_CACHE_DIR"):
    _use_kernel_cache_dir()

compile_lock.install()  # processes starting together compile each kernel once (compile_lock.py)
