"""Atomic file replacement: write beside the target, fsync, rename, fsync the directory.

A crash or kill at any point leaves either the old file or the new one, never a mix.
"""

from __future__ import annotations

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
    tmp.write_text(text, encoding="utf-8")
    publish(tmp, path)
