"""The registry of verification cases: what each case computes, against which reference, at
which resolutions, with which tolerance and which formal order of convergence.

A case is a function of one resolution (for DEM: time steps per contact duration) that runs a
scene and returns an `Outcome`: named error norms against the reference, the measured values,
conservation drift and the time spent stepping. The runner (runner.py) repeats it for timing,
fits the observed order and applies the tolerances declared here.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from ..simulation import advance

EPS = float(np.finfo(np.float64).eps)


@dataclass
class Outcome:
    """One run of a case at one resolution."""

    dt: float  # [s]
    steps: int  # time steps taken
    particles: int
    errors: dict[str, float]  # error norms against the reference (relative unless stated)
    values: dict[str, float] = field(default_factory=dict)  # measured quantities, for the tables
    drift: dict[str, float] = field(default_factory=dict)  # conservation drift (relative)
    step_seconds: float = 0.0  # wall time spent inside the time loop [s]
    work: float = 0.0  # machine-independent cost in work_unit (0: steps x particles)
    work_unit: str = "particle-step"


@dataclass(frozen=True)
class Tolerance:
    """error[metric] <= bound at every resolution >= min_resolution. The bound is a number, or
    `ulps_per_step` x steps x eps (round-off that grows by a few ulps per step)."""

    metric: str
    bound: float | None = None
    min_resolution: float = 0.0
    ulps_per_step: float | None = None
    source: str = ""

    def bound_for(self, steps: int) -> float:
        if self.bound is not None:
            return self.bound
        return float(self.ulps_per_step) * steps * EPS


@dataclass(frozen=True)
class VerificationCase:
    name: str
    title: str
    model: str  # what it exercises: a contact law ("linear", "hertz") or a fluid model
    reference: str  # the analytic or published result, cited
    description: str  # set-up and how the error is measured
    run: Callable[[float], Outcome]
    ladder: tuple[float, ...]  # full run
    quick_ladder: tuple[float, ...]  # --quick
    resolution: str = "steps per contact"
    error_labels: dict[str, str] = field(default_factory=dict)  # metric -> what it measures
    order_metrics: tuple[str, ...] = ()  # errors whose observed order is checked
    formal_order: float | None = None  # None: exact (round-off) or not a dt-convergence case
    min_order: float | None = None  # observed order must reach this (None: reported only)
    order_note: str = ""  # why the order is what it is (or is not checked)
    tolerances: tuple[Tolerance, ...] = ()
    drift_bounds: dict[str, float] = field(default_factory=dict)  # drift name -> largest allowed
    roundoff_floor: float = 1e-13  # errors below this are round-off: left out of the order fit
    # timed runs per resolution (None: the runner's): 1 for a case too costly to repeat, whose
    # runs are then not checked against each other (restarts and threads are checked bitwise by
    # tests/restart); its one run's wall time includes any compilation
    repeats: int | None = None


REGISTRY: dict[str, VerificationCase] = {}


def register(case: VerificationCase) -> VerificationCase:
    if case.name in REGISTRY:
        raise ValueError(f"verification case {case.name!r} registered twice")
    REGISTRY[case.name] = case
    return case


def cases() -> dict[str, VerificationCase]:
    """All registered cases (importing the modules that define them)."""
    from . import coupled_cases, dem_cases, fluid_cases, hertz_cases  # noqa: F401  (register on import)

    return REGISTRY


class Stepper:
    """advance() with the time spent in it accumulated (the cost of the integration alone)."""

    def __init__(self, scene):
        self.scene = scene
        self.seconds = 0.0
        self.steps = 0

    def advance(self, n: int = 1) -> None:
        start = time.perf_counter()
        advance(self.scene, n)
        self.seconds += time.perf_counter() - start
        self.steps += n
