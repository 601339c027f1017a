"""One compile of a kernel at a time across the processes that share the kernel cache.

The ranks of a split run, the members of `sphere sweep --local N`, a run beside its compile
helper (compile_ahead.py) and the workers of a test suite all start with the same kernels to
compile. Numba compiles each in every process that finds it missing from the cache, so N
processes starting together compile each kernel N times; on a node of fewer cores than
processes those compiles share the cores, and each takes N times longer. Here a process
compiling a cached kernel holds an advisory lock on a file beside the kernel's cache index
(fcntl.flock: released by the system if the process dies); another process needing the same
kernel waits, asleep, and then finds it in the cache and loads it. Kernels that are not the same
function still compile side by side. A lock that cannot be taken (a file system without flock)
leaves the compile as it was.

The time a process spends here (compiling, loading from the cache, waiting for another's
compile) is summed in `seconds_compiling`: the run's rate and ETA leave it out (io/progress.py),
and its report says how much of the run it was. The watchers in `watchers` are told when each
outermost compile begins and ends (the progress line says so when one takes long).
"""

from __future__ import annotations

import fcntl
import os
import time

from numba.core import sigutils
from numba.core.dispatcher import Dispatcher

_compile = Dispatcher.compile
_held: set[str] = set()  # the locks this process holds: a kernel's compile nests its callees'
_depth = 0  # compiles under way in this process (a kernel's nests its callees')
_seconds = 0.0  # wall seconds spent in the outermost compiles so far
_since = 0.0  # when the outermost compile under way began (the run compiles from one thread)
# called with True when an outermost compile begins and False when it ends
watchers: list = []


def seconds_compiling() -> float:
    """Wall seconds this process has spent compiling kernels (or loading them from the cache, or
    waiting for another process to compile them) so far, that in progress included."""
    return _seconds + (time.monotonic() - _since if _depth else 0.0)


def _lock_path(dispatcher) -> str | None:
    """The lock file of a dispatcher whose kernels Numba caches, else None."""
    cache = getattr(dispatcher, "_cache", None)
    impl = getattr(cache, "_impl", None)
    path = getattr(cache, "_cache_path", None)
    if impl is None or path is None:
        return None
    return os.path.join(path, f"{impl.filename_base}.lock")


def compile_alone(self, sig):
    """Dispatcher.compile, holding the kernel's lock while it compiles or loads, timed."""
    global _depth, _seconds, _since
    if _depth == 0:
        _since = time.monotonic()
        for watcher in tuple(watchers):
            watcher(True)
    _depth += 1
    try:
        return _compile_locked(self, sig)
    finally:
        _depth -= 1
        if _depth == 0:
            _seconds += time.monotonic() - _since
            for watcher in tuple(watchers):
                watcher(False)


def _compile_locked(self, sig):
    args, _ = sigutils.normalize_signature(sig)
    path = _lock_path(self)
    if path is None or path in _held or tuple(args) in self.overloads:
        return _compile(self, sig)
    try:
        handle = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
    except OSError:
        return _compile(self, sig)
    try:
        try:
            fcntl.flock(handle, fcntl.LOCK_EX)
        except OSError:
            return _compile(self, sig)
        _held.add(path)
        try:
            return _compile(self, sig)
        finally:
            _held.discard(path)
    finally:
        os.close(handle)  # releases the lock


def install() -> None:
    Dispatcher.compile = compile_alone
