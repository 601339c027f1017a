"""Processes starting together compile a kernel once (sphere_cli/compile_lock.py): two
processes call the same uncompiled kernel at the same moment with an empty cache; one compiles
it, the other waits for it and loads it from the cache (without the lock both compile)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time

# a kernel that takes about a second to compile: a long chain of arithmetic
KERNEL = (
    "from numba import njit\n\n\n@njit(cache=True)\ndef slow(x):\n    s = x\n"
    + "".join(f"    s = s * {1.0 + k * 1e-3} + math.sin(s + {k}.0)\n" for k in range(150))
    + "    return s\n"
)

CALLER = """\
import json, sys, time
from pathlib import Path

import sphere_cli  # noqa: F401 - installs the lock

sys.path.insert(0, sys.argv[1])
import slow_kernel

Path(sys.argv[2]).write_text("ready")
while not Path(sys.argv[3]).exists():
    time.sleep(0.001)
slow_kernel.slow(1.0)
stats = slow_kernel.slow.stats
print(json.dumps([sum(stats.cache_misses.values()), sum(stats.cache_hits.values())]))
"""


def test_two_processes_compile_a_kernel_once(tmp_path):
    (tmp_path / "slow_kernel.py").write_text("import math\n" + KERNEL)
    (tmp_path / "caller.py").write_text(CALLER)
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "cache")}
    env.pop("NUMBA_CACHE_DIR", None)
    go = tmp_path / "go"
    command = [sys.executable, str(tmp_path / "caller.py"), str(tmp_path)]
    callers = [
        subprocess.Popen(
            [*command, str(tmp_path / f"ready{k}"), str(go)],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
            env=env,
        )  # fmt: skip
        for k in range(2)
    ]
    started = time.monotonic()
    while not all((tmp_path / f"ready{k}").exists() for k in range(2)):
        assert time.monotonic() - started < 120 and all(c.poll() is None for c in callers)
        time.sleep(0.01)
    go.write_text("")
    results = []
    for caller in callers:
        out, err = caller.communicate(timeout=300)
        assert caller.returncode == 0, err
        results.append(json.loads(out.strip().splitlines()[-1]))
    # [compiled, loaded from the cache]: one of each
    assert sorted(results) == [[0, 1], [1, 0]]
    assert list((tmp_path / "cache").rglob("*slow*.lock"))  # the lock beside the kernel's index
