"""`sphere bench dem|fluid|darcy|vans1d|grid|compile`: benchmarks, never part of the tests' timings.

    dem      particle-steps per second on the canonical DEM scene (dem.py)
    ranks    its settled bed on several MPI ranks, side by side (ranks.py)
    fluid    the porous Navier-Stokes fluid coupled to a DEM bed (fluid.py)
    darcy    the Darcy model coupled to the DEM (darcy.py)
    vans1d   the 1D VANS bedload case (vans1d.py)
    grid     the fluids' shared plumbing: the pressure solvers and the porosity (grid.py)
    compile  the seconds a dry scene waits for its kernels, cold and cached (compile.py)

Shared here: the stopwatch that times a method inside the step, the timing of whole steps, and
what is recorded of the machine.
"""

from __future__ import annotations

import time

import numba
import numpy as np

from ..runtime import cache_sizes
from ..simulation import advance


class Stopwatch:
    """Wraps a method (`owner.name`) so that each call inside the step is timed: wall and
    process CPU seconds of every call. A step hook is taken by the scene once, so with `scene`
    the scene takes its hooks anew when the stopwatch is put on and taken off."""

    def __init__(self, owner, name: str, scene=None):
        self.owner, self.name, self.scene = owner, name, scene
        self.method = getattr(owner, name)
        self.seconds: list[float] = []
        self.cpu: list[float] = []
        setattr(owner, name, self)
        if scene is not None:
            scene.order_modules()

    def __call__(self, *args, **kwargs):
        start, cpu = time.perf_counter(), time.process_time()
        result = self.method(*args, **kwargs)
        self.seconds.append(time.perf_counter() - start)
        self.cpu.append(time.process_time() - cpu)
        return result

    def restore(self) -> None:
        setattr(self.owner, self.name, self.method)
        if self.scene is not None:
            self.scene.order_modules()


def timed_steps(scene, steps: int) -> tuple[list[float], list[float]]:
    """Wall and process CPU time of each of `steps` steps [s]."""
    wall, cpu = [], []
    for _ in range(steps):
        start, start_cpu = time.perf_counter(), time.process_time()
        advance(scene, 1)
        wall.append(time.perf_counter() - start)
        cpu.append(time.process_time() - start_cpu)
    return wall, cpu


def machine() -> dict:
    """What ran a benchmark: the processor by name and the one Numba compiles for (the same
    figures on another processor do not compare), the cores, the versions."""
    import os
    import platform

    import llvmlite.binding

    from ..verify.suite import _cpu_model

    return {
        "processor": _cpu_model(),
        "compiled_for": llvmlite.binding.get_host_cpu_name(),
        "caches": cache_sizes(),
        "cpu_count": os.cpu_count(),
        "platform": platform.platform(),
        "numba": numba.__version__,
        "numpy": np.__version__,
        "threading_layer_requested": numba.config.THREADING_LAYER,
        # how idle threads wait between parallel regions: the two-thread figures depend on it
        "omp_wait_policy": os.environ.get("OMP_WAIT_POLICY", "").strip().upper() or "default",
    }
