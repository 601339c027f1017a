"""Unit tests of the verification machinery: the least-squares order, the verdicts, the layout
of verify.json, the command's exit codes, and the outputs without matplotlib. Synthetic cases
with a known error law (no simulation) stand in for the real ones."""

from __future__ import annotations

import dataclasses
import json
import math

import pytest
from typer.testing import CliRunner

from sphere_cli.cli import app
from sphere_cli.verify import REGISTRY, Outcome, Tolerance, VerificationCase, observed_order, run_verification
from sphere_cli.verify import report as report_module


def test_observed_order_of_a_power_law_is_exact():
    res = [10, 20, 40, 80]
    assert observed_order(res, [3.0 * r**-2 for r in res]) == pytest.approx(2.0, abs=1e-12)
    assert observed_order(res, [0.5 * r**-1 for r in res]) == pytest.approx(1.0, abs=1e-12)


def test_observed_order_is_the_least_squares_slope():
    """Errors off a power law by factors 1.2, 1/1.2: the fit is the slope of the regression line
    through the logs, not the slope between the end points."""
    res = [10.0, 20.0, 40.0, 80.0]
    err = [r**-2 * f for r, f in zip(res, (1.2, 1 / 1.2, 1.2, 1 / 1.2), strict=True)]
    x = [math.log(r) for r in res]
    y = [math.log(e) for e in err]
    mx, my = sum(x) / 4, sum(y) / 4
    slope = sum((a - mx) * (b - my) for a, b in zip(x, y, strict=True)) / sum((a - mx) ** 2 for a in x)
    assert observed_order(res, err) == pytest.approx(-slope, rel=1e-12)
    assert observed_order(res, err) != pytest.approx(2.0, abs=0.05)


def test_observed_order_leaves_out_round_off_and_needs_two_points():
    res = [10, 20, 40, 80]
    err = [1e-4, 2.5e-5, 1e-16, 0.0]
    assert observed_order(res, err, floor=1e-13) == pytest.approx(2.0, abs=1e-12)
    assert observed_order([10, 20], [1e-4, 1e-16], floor=1e-13) is None
    assert observed_order([10], [1e-4]) is None
    assert observed_order([10, 20], [float("nan"), 1e-5]) is None


def _synthetic(name: str, order: float, bound: float, min_order: float | None = None) -> VerificationCase:
    def run(res: float) -> Outcome:
        return Outcome(
            dt=1.0 / res,
            steps=int(res),
            particles=2,
            errors={"err": 3.0 * res**-order, "other": 1.0 / res},
            values={"x": res},
            drift={"momentum": 0.0},
            step_seconds=1e-4 * res,
        )

    return VerificationCase(
        name=name,
        title="synthetic error law",
        model="none",
        reference="err = 3 res^-p",
        description="no simulation",
        run=run,
        ladder=(10, 20, 40, 80),
        quick_ladder=(10, 20),
        error_labels={"err": "the error"},
        order_metrics=("err",),
        formal_order=2.0,
        min_order=min_order,
        order_note="by construction",
        tolerances=(Tolerance("err", bound, 20, source="test"),),
        drift_bounds={"momentum": 1e-14},
    )


@pytest.fixture
def synthetic(monkeypatch):
    monkeypatch.setitem(REGISTRY, "zz-good", _synthetic("zz-good", 2.0, 1e-2, min_order=1.8))
    monkeypatch.setitem(REGISTRY, "zz-bad-order", _synthetic("zz-bad-order", 1.0, 1.0, min_order=1.8))
    monkeypatch.setitem(REGISTRY, "zz-bad-tolerance", _synthetic("zz-bad-tolerance", 2.0, 1e-6))


def test_verify_json_layout(tmp_path, synthetic):
    report = run_verification(["zz-good"], out_dir=tmp_path, repeats=3)
    data = json.loads((tmp_path / "verify.json").read_text())
    assert data["schema"] == "sphere-verify/1"
    assert data["mode"] == "full" and data["repeats"] == 3 and data["passed"] is True
    assert {"host", "cpus", "cpus_usable", "threads", "numba", "numpy", "python", "commit"} <= set(
        data["machine"]
    )
    assert data["machine"]["threads"] == 1
    (case,) = data["cases"]
    assert case["name"] == "zz-good" and case["passed"] is True
    assert case["formal_order"] == 2.0 and case["min_order"] == 1.8
    assert case["orders"]["err"] == pytest.approx(2.0) and case["orders"]["other"] == pytest.approx(1.0)
    assert case["tolerances"] == [
        {"metric": "err", "bound": 1e-2, "ulps_per_step": None, "min_resolution": 20, "source": "test"}
    ]
    assert case["first_call_s"] >= 0 and case["compile_s"] >= 0
    assert [r["resolution"] for r in case["rows"]] == [10, 20, 40, 80]
    row = case["rows"][1]
    assert row["errors"] == {"err": pytest.approx(3.0 / 400), "other": pytest.approx(0.05)}
    assert row["steps"] == 20 and row["particles"] == 2 and row["dt"] == pytest.approx(0.05)
    assert len(row["wall_s_all"]) == 3 and row["wall_s"] == sorted(row["wall_s_all"])[1]
    assert row["step_s"] == pytest.approx(2e-3)
    assert row["time_per_work_s"] == pytest.approx(2e-3 / 40)
    assert row["work"] == 40 and row["work_unit"] == "particle-step"
    assert {c["check"] for c in case["checks"]} >= {"order of err >= 1.8", "momentum drift <= 1e-14"}
    assert report["cases"][0]["name"] == "zz-good"
    assert (tmp_path / "zz-good.md").is_file()


def test_missed_tolerance_and_order_fail_the_case(tmp_path, synthetic):
    report = run_verification(["zz-bad-order", "zz-bad-tolerance"], quick=True, out_dir=tmp_path)
    assert report["passed"] is False
    assert report["failed"] == ["zz-bad-order", "zz-bad-tolerance"]
    by_name = {c["name"]: c for c in report["cases"]}
    order_check = [c for c in by_name["zz-bad-order"]["checks"] if c["check"].startswith("order")]
    assert order_check and not order_check[0]["passed"]
    tol_check = [c for c in by_name["zz-bad-tolerance"]["checks"] if c["check"].startswith("err <=")]
    assert tol_check and not tol_check[0]["passed"] and "at 20" in tol_check[0]["detail"]


def test_a_tolerance_no_resolution_reaches_fails(tmp_path, monkeypatch):
    case = dataclasses.replace(_synthetic("zz-unchecked", 2.0, 1.0), quick_ladder=(10, 15))
    monkeypatch.setitem(REGISTRY, "zz-unchecked", case)
    report = run_verification(["zz-unchecked"], quick=True, out_dir=tmp_path)
    assert not report["passed"]
    assert "no resolution >= 20" in report["cases"][0]["checks"][0]["detail"]


def test_cli_exit_codes(tmp_path, synthetic):
    runner = CliRunner()
    good = runner.invoke(app, ["verify", "zz-good", "-o", str(tmp_path / "a")])
    assert good.exit_code == 0, good.output
    bad = runner.invoke(app, ["verify", "zz-bad-order", "--quick", "-o", str(tmp_path / "b")])
    assert bad.exit_code == 70
    unknown = runner.invoke(app, ["verify", "no-such-case", "-o", str(tmp_path / "c")])
    assert unknown.exit_code == 2
    assert not (tmp_path / "c").exists()
    listing = runner.invoke(app, ["verify", "--list"])
    assert listing.exit_code == 0
    for name in ("a1-linear-pair", "a4-free-fall", "stability-nan-guard", "zz-good"):
        assert name in listing.output


def test_outputs_without_matplotlib(tmp_path, synthetic, monkeypatch):
    """Without matplotlib: no PNG, the tables and verify.json are still written, and the user
    is told how to get the plots."""
    monkeypatch.setattr(report_module, "_pyplot", lambda: None)
    report = run_verification(["zz-good"], out_dir=tmp_path)
    assert any("pip install 'sphere-cli[plot]'" in note for note in report["notes"])
    assert not list(tmp_path.glob("*.png"))
    assert (tmp_path / "zz-good.md").is_file()
    assert json.loads((tmp_path / "verify.json").read_text())["cases"][0]["plot"] is None
