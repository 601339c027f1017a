"""Atomic file replacement: write beside the target, fsync, rename, fsync the directory.

A crash or kill at any point leaves either the old file or the new one, never a mix.
"""

from __future__ import annotations

import errno
import os
from pathlib import Path


def fsync_path(path: Path) -> None:
    fd = os.open(path, os.O_RDONLY)
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


def publish(tmp: Path, final: Path) -> None:
    """Make the finished file `tmp` appear as `final` in one step."""
    fsync_path(tmp)
    os.replace(tmp, final)
    fsync_path(final.parent)


def write_text_atomic(path: Path, text: str) -> None:
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        tmp.write_text(text, encoding="utf-8")
        publish(tmp, path)
    except OSError:
        tmp.unlink(missing_ok=True)
        raise


# Room left beyond a write's own bytes: HDF5 adds chunk indices and metadata as a file grows.
FREE_SPACE_MARGIN = 1 << 20


def require_free_space(path: Path, nbytes: int) -> None:
    """Raise OSError(ENOSPC) before a write into the HDF5 library that would not fit: HDF5 meets
    a full disk in the middle of its own writes and then crashes the process, where a plain write
    fails cleanly."""
    stats = os.statvfs(path.parent)
    free = stats.f_bavail * stats.f_frsize
    need = 2 * nbytes + FREE_SPACE_MARGIN
    if free < need:
        raise OSError(
            errno.ENOSPC,
            f"No space left on device: {free / 2**20:.1f} MiB free, "
            f"the write needs about {need / 2**20:.1f} MiB",
        )
