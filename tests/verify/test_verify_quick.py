"""`sphere verify --quick`: every verification case over its quick ladder must meet its
tolerance and its order of convergence (registry in sphere_cli/verify/); once through the CLI.

Each case states its reference (verification group A1, A4, or a closed form) in its
registry entry; this test fails when a case misses a tolerance, falls short of its order, is
not deterministic across repeats, or crashes.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys

import pytest

from sphere_cli.verify import cases, run_case

CASES = list(cases())


def _failures(record: dict) -> str:
    failed = [f"{c['check']}: {c['detail']}" for c in record["checks"] if not c["passed"]]
    return "; ".join(failed) + (f"\n{record.get('traceback', '')}" if record.get("error") else "")


@pytest.mark.parametrize("name", CASES)
def test_quick_case_meets_tolerance_and_order(name):
    # one repeat shows determinism: it and the first rung's untimed call must agree bitwise; the
    # further repeats of `sphere verify` only steady the reported timings
    record = run_case(cases()[name], quick=True, repeats=1)
    assert record["passed"], _failures(record)
    assert len(record["rows"]) == len(cases()[name].quick_ladder)
    assert record["checks"], "a case with no checks cannot fail"


def test_every_case_checks_something_at_its_quick_ladder():
    """A tolerance that no quick resolution reaches would be skipped silently: the runner fails
    it instead, and every case has at least one tolerance (or a checked order)."""
    for case in cases().values():
        assert case.tolerances or case.min_order is not None, case.name
        for tol in case.tolerances:
            assert max(case.quick_ladder) >= tol.min_resolution, (case.name, tol.metric)
        if case.min_order is not None:
            assert len(case.quick_ladder) >= 2, case.name


def test_cli_verify_one_case_quick(tmp_path):
    """The real command: exit 0, verify.json, a Markdown table and (with matplotlib) a plot."""
    out = tmp_path / "results"
    proc = subprocess.run(
        [sys.executable, "-m", "sphere_cli.cli", "verify", "a1-linear-pair", "--quick", "-o", str(out)],
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)},
    )
    assert proc.returncode == 0, proc.stderr
    assert "pass  a1-linear-pair" in proc.stdout
    report = json.loads((out / "verify.json").read_text())
    assert report["passed"] and [c["name"] for c in report["cases"]] == ["a1-linear-pair"]
    assert report["stability"] == []
    assert (out / "a1-linear-pair.md").read_text().startswith("## `a1-linear-pair`")
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        assert "pip install" in proc.stderr
    else:
        png = out / "a1-linear-pair.png"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert png.stat().st_size < 200_000


# the cases whose full ladder starts below their quick one (the others' coarsest rung runs above),
# but for a ladder of run durations, whose shorter run is the start of the quick one
BEYOND_QUICK = [
    name
    for name, case in cases().items()
    if min(case.ladder) not in case.quick_ladder and case.resolution != "simulated seconds"
]


@pytest.mark.parametrize("name", BEYOND_QUICK)
def test_coarsest_rung_of_the_full_ladder_runs(name):
    """The full run (`make verify`) reaches resolutions the quick one does not: its coarsest
    rung, the one closest to the builder's dt limit, must build and run (a case of the forces
    of the first state, d3-vans1d-sphere-forces, builds and evaluates them without a step)."""
    case = cases()[name]
    outcome = case.run(min(case.ladder))
    assert outcome.steps > 0 or outcome.work > 0
    assert all(math.isfinite(v) for v in outcome.errors.values())
