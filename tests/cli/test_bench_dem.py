"""`sphere bench dem` (the canonical DEM scene) at a tiny size: every row of the report
holds the figures docs/performance.md quotes, with consistent values. No timing is asserted
(a shared machine makes any bound loose or flaky); the settled state is left out (it settles a
bed for 0.15 s of simulated time)."""

from __future__ import annotations

import json
import os

import pytest
from cli_test_support import sphere_inproc


def test_dem_bench_reports_rate_contacts_memory_and_speedup(tmp_path):
    result = sphere_inproc(
        "bench", "dem", "--sizes", "216", "--states", "loose", "--threads", "1,2", "--steps", "3",
        "--repeats", "2", "-o", tmp_path / "out", "--fixed-cost-sizes", "10,40",
    )  # fmt: skip
    assert result.code == 0, result.stdout + result.stderr
    report = json.loads((tmp_path / "out" / "bench.json").read_text())
    assert report["steps"] == 3 and report["repeats"] == 2
    assert report["first_call_seconds"] > 0
    # figures compare only on the same processor: it is named, with its caches and Numba's target
    machine = report["machine"]
    assert machine["processor"] and machine["compiled_for"] and machine["cpu_count"] >= 1
    assert set(machine["caches"]) >= {"L1", "L2"}
    rows = report["rows"]
    assert [r["threads"] for r in rows] == [1, 2][: len(rows)] and rows
    for row in rows:
        assert row["n"] == 216 and row["state"] == "loose" and row["steps"] == 3
        assert len(row["all_seconds"]) == 2 and min(row["all_seconds"]) > 0
        assert row["particle_steps_per_second"] == 216 * 3 / row["seconds"]
        assert row["best_particle_steps_per_second"] >= row["particle_steps_per_second"]
        # the loose lattice (spacing 1.2 d) has no contacts, and every array costs memory
        assert row["contacts_per_particle"] == 0.0
        assert row["bytes_per_particle"] > 200
        # each hook of the step timed where the step calls it; the step so taken counts them all
        parts = dict(row["parts_ns_per_particle_step"])
        whole = parts.pop("step")
        hooks = {"Motion.kick_drift", "NeighborSearch.prepare", "PairContactForces.forces", "Motion.kick"}
        assert set(parts) >= hooks and "PlaneWallForces.forces" in parts  # the canonical box's walls
        assert all(ns > 0.0 for ns in parts.values())
        assert sum(parts.values()) <= whole
    if len(rows) == 2:
        one, two = rows
        assert two["speedup"] == two["particle_steps_per_second"] / one["particle_steps_per_second"]
    # how idle threads wait changes the figures of two threads: recorded, and said where they sleep
    policy = os.environ.get("OMP_WAIT_POLICY", "").strip().upper() or "default"
    assert machine["omp_wait_policy"] == policy
    assert ("(OMP_WAIT_POLICY=PASSIVE: the threads sleep" in result.stdout) == (
        policy == "PASSIVE" and len(rows) == 2
    )
    assert f"N = {216:>7}" in result.stdout
    assert "ns a particle-step through the hooks: Motion.kick_drift" in result.stdout
    # the fixed cost: a straight line through the step times of the two sizes
    fixed = report["fixed_cost"]
    assert fixed["sizes"] == [10, 40] and len(fixed["step_seconds"]) == 2
    (t10, t40) = fixed["step_seconds"]
    assert fixed["intercept_seconds"] == pytest.approx(t10 - 10 * (t40 - t10) / 30, rel=1e-9, abs=1e-12)
    assert "fixed cost of a step" in result.stdout
