"""Run verification cases over their resolution ladders: timing, observed orders, verdicts.

Each resolution is run once untimed at the start of a case (the first call: it pays for
loading or compiling the Numba kernels, reported apart as first_call_s/compile_s), then
`repeats` times; the median wall time is reported, and the repeats must agree bitwise (the
runs are deterministic). A case too costly for that (VerificationCase.repeats = 1) is run
once per resolution, its compilation in the first row's time. The observed order is the
least-squares slope of log(error) against log(resolution), over the rows whose error is above
the case's round-off floor.
"""

from __future__ import annotations

import math
import statistics
import time
import traceback

import numpy as np

from .registry import Outcome, VerificationCase


def observed_order(resolutions, errors, floor: float = 0.0) -> float | None:
    """-slope of the least-squares line through (log resolution, log error), using the points
    with a finite error above `floor`; None with fewer than two such points. Resolution is a
    number of steps (per contact), so a scheme of order p gives error ~ resolution^-p."""
    pts = [
        (math.log(r), math.log(e))
        for r, e in zip(resolutions, errors, strict=True)
        if e is not None and math.isfinite(e) and e > floor and r > 0
    ]
    if len(pts) < 2 or len({x for x, _ in pts}) < 2:
        return None
    x = np.array([p[0] for p in pts])
    y = np.array([p[1] for p in pts])
    slope = float(np.polyfit(x, y, 1)[0])
    return -slope


def _row(resolution: float, outcome: Outcome, walls: list[float], step_walls: list[float]) -> dict:
    step_s = statistics.median(step_walls)
    work = outcome.work or outcome.steps * outcome.particles
    return {
        "resolution": resolution,
        "dt": outcome.dt,
        "steps": outcome.steps,
        "particles": outcome.particles,
        "errors": dict(outcome.errors),
        "values": dict(outcome.values),
        "drift": dict(outcome.drift),
        "wall_s": statistics.median(walls),
        "wall_s_all": walls,
        "step_s": step_s,
        "work": work,
        "work_unit": outcome.work_unit,
        "time_per_work_s": step_s / work if work else None,
    }


def _same(a: Outcome, b: Outcome) -> bool:
    return a.errors == b.errors and a.values == b.values and a.drift == b.drift and a.steps == b.steps


def run_case(case: VerificationCase, quick: bool = False, repeats: int = 3, log=None) -> dict:
    """Run one case over its ladder; returns its JSON record (rows, orders, checks, verdict)."""
    ladder = case.quick_ladder if quick else case.ladder
    repeats = case.repeats or repeats
    warm_up = case.repeats != 1  # one untimed first call, unless the case runs once
    say = log or (lambda _msg: None)
    record = {
        "name": case.name,
        "title": case.title,
        "model": case.model,
        "reference": case.reference,
        "description": case.description,
        "resolution": case.resolution,
        "error_labels": dict(case.error_labels),
        "formal_order": case.formal_order,
        "min_order": case.min_order,
        "order_metrics": list(case.order_metrics),
        "order_note": case.order_note,
        "tolerances": [
            {
                "metric": t.metric,
                "bound": t.bound,
                "ulps_per_step": t.ulps_per_step,
                "min_resolution": t.min_resolution,
                "source": t.source,
            }
            for t in case.tolerances
        ],
        "drift_bounds": dict(case.drift_bounds),
        "repeats": repeats,
        "rows": [],
        "orders": {},
        "checks": [],
        "error": None,
    }
    checks = record["checks"]
    started = time.perf_counter()
    try:
        for i, resolution in enumerate(ladder):
            first = None
            if i == 0 and warm_up:
                t0 = time.perf_counter()
                first = case.run(resolution)
                record["first_call_s"] = time.perf_counter() - t0
            outcomes, walls, step_walls = [], [], []
            for _ in range(repeats):
                t0 = time.perf_counter()
                outcome = case.run(resolution)
                walls.append(time.perf_counter() - t0)
                step_walls.append(outcome.step_seconds)
                outcomes.append(outcome)
            reference = first or outcomes[0]
            if not all(_same(reference, o) for o in outcomes):
                checks.append(
                    {
                        "check": f"repeats agree at {resolution:g}",
                        "passed": False,
                        "detail": "the runs of one resolution differ: the case is not deterministic",
                    }
                )
            row = _row(resolution, outcomes[0], walls, step_walls)
            record["rows"].append(row)
            if i == 0 and warm_up:
                record["compile_s"] = max(0.0, record["first_call_s"] - row["wall_s"])
            say(
                f"  {case.name}: {resolution:g} {case.resolution}: "
                + ", ".join(f"{k} {v:.3g}" for k, v in row["errors"].items())
                + f" ({row['wall_s']:.2f} s)"
            )
    except Exception as exc:  # a case that crashes fails, with its traceback kept for the report
        record["error"] = f"{type(exc).__name__}: {exc}"
        record["traceback"] = traceback.format_exc()
        checks.append({"check": "runs", "passed": False, "detail": record["error"]})
    record["total_s"] = time.perf_counter() - started
    _judge(case, record)
    return record


def _judge(case: VerificationCase, record: dict) -> None:
    rows = record["rows"]
    checks = record["checks"]
    resolutions = [r["resolution"] for r in rows]
    metrics = list(rows[0]["errors"]) if rows else []
    for metric in metrics:
        record["orders"][metric] = observed_order(
            resolutions, [r["errors"][metric] for r in rows], case.roundoff_floor
        )
    if record["error"] is None:
        for tol in case.tolerances:
            applicable = [r for r in rows if r["resolution"] >= tol.min_resolution]
            if not applicable:
                checks.append(
                    {
                        "check": f"{tol.metric} tolerance",
                        "passed": False,
                        "detail": f"no resolution >= {tol.min_resolution:g} in the ladder to check it at",
                    }
                )
                continue
            worst = max(applicable, key=lambda r: r["errors"][tol.metric] / tol.bound_for(r["steps"]))
            bound = tol.bound_for(worst["steps"])
            value = worst["errors"][tol.metric]
            checks.append(
                {
                    "check": f"{tol.metric} <= {bound:.3g} at >= {tol.min_resolution:g} {case.resolution}",
                    "passed": bool(value <= bound),
                    "detail": f"worst {value:.3g} at {worst['resolution']:g}",
                }
            )
        if case.min_order is not None:
            for metric in case.order_metrics:
                order = record["orders"].get(metric)
                checks.append(
                    {
                        "check": f"order of {metric} >= {case.min_order:g}",
                        "passed": order is not None and order >= case.min_order,
                        "detail": "too few points above round-off"
                        if order is None
                        else f"observed {order:.2f}",
                    }
                )
        for name, bound in case.drift_bounds.items():
            worst_drift = max(r["drift"].get(name, 0.0) for r in rows)
            checks.append(
                {
                    "check": f"{name} drift <= {bound:.3g}",
                    "passed": bool(worst_drift <= bound),
                    "detail": f"worst {worst_drift:.3g}",
                }
            )
    record["passed"] = bool(checks) and all(c["passed"] for c in checks)
