"""`sphere bench fluid` (sphere_cli/bench/fluid.py) at a tiny size: the report holds
every figure docs/performance.md quotes, with consistent values. No timing is asserted (a shared machine
makes any bound either loose or flaky); only that times are positive and parts fit in wholes."""

from __future__ import annotations

import json
import math

from cli_test_support import sphere_inproc


def test_fluid_bench_reports_cells_particles_steps_and_both_pressure_solvers(tmp_path):
    """8^3 cells, 200 particles, 2 coupled steps on one thread; Jacobi capped at 50 iterations
    (it needs ~600 at 8^3 from the warm start), so the report must say it did not converge."""
    result = sphere_inproc(
        "bench", "fluid", "--cells", "8", "--particles", "200", "--steps", "2", "--threads", "1",
        "--jacobi-max-iterations", "50", "-o", tmp_path / "out",
    )  # fmt: skip
    assert result.code == 0, result.stdout + result.stderr
    report = json.loads((tmp_path / "out" / "bench-fluid.json").read_text())
    assert report["case"] == "fluid"
    assert report["particles"] == 200
    assert report["cells"] == [8, 8, 8] and report["cell_count"] == 512
    assert report["coupling_steps"] == 1 and report["steps"] == 2
    assert report["compile_seconds"] > 0 and report["first_step_seconds"] > 0
    assert report["threading_layer"] in ("omp", "tbb", "workqueue")
    assert len(report["load_average_before"]) == len(report["load_average_after"]) == 3
    assert report["tolerance"] == 1e-10  # the default of fluid.solver.tolerance
    assert report["jacobi_limits"] == {"max_iterations": 50, "seconds": 60.0}
    (row,) = report["rows"]
    assert row["threads"] == 1
    for key, value in row.items():
        if key.endswith("seconds"):
            assert math.isfinite(value) and value > 0, (key, value)
    assert row["fluid_step_seconds"] <= row["coupled_step_seconds"]
    assert row["pressure_solve_seconds"] <= row["fluid_step_seconds"]
    assert row["fluid_cell_updates_per_second"] == 512 / row["fluid_step_seconds"]
    assert row["explicit_cell_updates_per_second"] > row["fluid_cell_updates_per_second"]
    assert row["pressure_iterations"] >= 1
    fast, jacobi = row["fast_solver_same_system"], row["jacobi_same_system"]
    assert fast["converged"] and fast["residual"] <= 1e-10 and 1 <= fast["iterations"] < 50
    assert not jacobi["converged"] and jacobi["iterations"] == 50 and jacobi["residual"] > 1e-10
    assert "M cell-updates/s" in result.stdout
    assert "Jacobi did not converge in 50 iterations" in result.stdout
