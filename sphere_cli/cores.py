"""A warning for runs whose OpenMP threads would share their cores with other busy processes.

Numba's OpenMP threads spin while they wait for each other. On cores of their own that is the
fastest way to wait; when another busy process holds one of those cores, every parallel region
waits for a thread that is not running, and a run on 2 threads measured 25-30 x slower than on
one (docs/performance.md). OMP_WAIT_POLICY=PASSIVE makes the threads sleep instead."""

from __future__ import annotations

import os
import time

# how long the other processes' use of the cores is sampled [s]; /proc/stat counts in 1/100 s
SAMPLE_SECONDS = 0.1
# a busy process sharing our cores holds most of one; half of one is the margin for noise
MARGIN_CORES = 0.5


def busy_cores(stat_before: str, stat_after: str) -> float:
    """Cores kept busy between two readings of /proc/stat (user, nice, system, irq and softirq
    time; idle, iowait and a hypervisor's steal are not busy here), from its first line."""
    before = [int(v) for v in stat_before.split("\n", 1)[0].split()[1:]]
    after = [int(v) for v in stat_after.split("\n", 1)[0].split()[1:]]
    delta = [a - b for a, b in zip(after, before, strict=False)]
    total = sum(delta[:8])  # user nice system idle iowait irq softirq steal (guest is in user)
    if total <= 0:
        return 0.0
    busy = delta[0] + delta[1] + delta[2] + delta[5] + delta[6]
    cores = os.cpu_count() or 1
    return cores * busy / total


def measure_busy_cores(seconds: float = SAMPLE_SECONDS) -> float | None:
    """Cores that other processes keep busy now (this one sleeps while it samples); None where
    /proc/stat cannot be read (not Linux)."""
    try:
        with open("/proc/stat", encoding="ascii") as f:
            before = f.read()
        time.sleep(seconds)
        with open("/proc/stat", encoding="ascii") as f:
            after = f.read()
    except OSError:
        return None
    return busy_cores(before, after)


def shared_cores_note(
    threads: int,
    cores: int | None = None,
    busy: float | None = None,
    wait_policy: str | None = None,
    layer: str | None = None,
) -> str | None:
    """The warning to give before a run on `threads` threads, or None. The arguments after
    `threads` default to this machine's: its core count, the cores other processes keep busy
    now (measured only when needed), OMP_WAIT_POLICY and NUMBA_THREADING_LAYER."""
    if threads < 2:
        return None
    if wait_policy is None:
        wait_policy = os.environ.get("OMP_WAIT_POLICY", "")
    if wait_policy.strip().lower() == "passive":
        return None
    if layer is None:
        layer = os.environ.get("NUMBA_THREADING_LAYER", "default")
    if layer.strip().lower() in ("workqueue", "tbb"):
        return None  # threads that do not spin (TBB yields after a short spin)
    if cores is None:
        cores = os.cpu_count() or 1
    if busy is None:
        busy = measure_busy_cores()
        if busy is None:
            return None
    free = cores - busy
    if threads <= free + MARGIN_CORES:
        return None
    return (
        f"other processes keep {busy:.1f} of this machine's {cores} cores busy, which leaves fewer "
        f"than the {threads} threads of this run; OpenMP threads spin while they wait, so sharing "
        "cores can slow the run many times over: set OMP_WAIT_POLICY=PASSIVE, or fewer threads "
        "(simulation.threads, NUMBA_NUM_THREADS)"
    )
