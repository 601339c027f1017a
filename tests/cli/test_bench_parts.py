"""`sphere bench darcy|vans1d|grid` at tiny sizes: each runs through the command line and
reports its rows; `sphere bench compile` with its timed child replaced (a cold compile takes
15-40 s). No timing is asserted (a shared machine makes any bound loose or flaky)."""

from __future__ import annotations

import json
import re
import statistics
import subprocess
from pathlib import Path

import numba
from cli_test_support import assert_clean_error, sphere_inproc

BEDLOAD = Path(__file__).parents[2] / "configs" / "bedload.toml"


def rows(stdout: str, first: str) -> list[list[str]]:
    """The table rows of the report that begin with `first`, split at the bars."""
    return [[c.strip() for c in line.split("|")] for line in stdout.splitlines() if line.startswith(first)]


def test_darcy_bench_times_the_coupled_step_and_its_parts():
    result = sphere_inproc(
        "bench", "darcy", "--cells", "8", "--particles", "200", "--steps", "2", "--threads", "1"
    )
    assert result.code == 0, result.stdout + result.stderr
    assert "8^3 cells, 200 particles" in result.stdout
    (row,) = rows(result.stdout, "1 |")
    assert len(row) == 7  # threads, step, porosity, pressure step, iterations, forces, DEM alone
    assert all(re.fullmatch(r"[0-9.]+( \([0-9.]+\))?", cell) for cell in row)


def test_grid_bench_times_each_solver_on_both_coefficient_fields():
    result = sphere_inproc(
        "bench", "grid", "--sizes", "8", "--threads", "1", "--methods", "pcg-jacobi,jacobi", "--repeats", "1"
    )
    assert result.code == 0, result.stdout + result.stderr
    found = rows(result.stdout, "8^3 |")
    assert [(r[1], r[2]) for r in found] == [
        ("a = 1", "pcg-jacobi"), ("a = 1", "jacobi"), ("porosity", "pcg-jacobi"), ("porosity", "jacobi"),
    ]  # fmt: skip
    assert all(int(r[4]) >= 1 for r in found)  # iterations


def test_grid_bench_refuses_an_unknown_solver():
    result = sphere_inproc("bench", "grid", "--methods", "multigrid")
    assert_clean_error(result, 2, "--methods", "pcg-multigrid, pcg-jacobi, jacobi")


def test_a_results_folder_that_cannot_be_written_is_refused_before_the_runs(tmp_path):
    """`-o` under a plain file: sphere verify ran every case and then ended in a traceback
    (FileNotFoundError) when it wrote verify.json; the benchmarks likewise. Now exit 74 at once,
    naming the folder."""
    (tmp_path / "file").write_text("")
    folder = tmp_path / "file" / "results"
    for command in (("verify", "a4-free-fall", "--quick"), ("bench", "dem", "--sizes", "100")):
        result = sphere_inproc(*command, "-o", folder)
        assert_clean_error(result, 74, str(folder), "cannot write the results there")


def test_counts_below_one_and_threads_beyond_the_machine_are_refused_by_option():
    """--sizes 0 divided by zero, --threads 0 or more threads than Numba may start ended in a
    traceback (or were skipped without a word), --ranks 0 ran one rank under the name 0."""
    most = numba.config.NUMBA_NUM_THREADS
    for command, option, fragment in (
        (("dem", "--sizes", "0"), "--sizes", "at least 1"),
        (("dem", "--threads", "0"), "--threads", "at least 1"),
        (("ranks", "--ranks", "1,0"), "--ranks", "at least 1"),
        (("darcy", "--threads", str(most + 1)), "--threads", f"at most {most} here"),
        (("dem", "--threads", f"1,{most + 1}"), "--threads", f"at most {most} here"),
        (("vans1d", "--threads", str(most + 1)), "--threads", f"at most {most} here"),
        (("compile", "--threads", f"1,{most + 1}"), "--threads", f"at most {most} here"),
    ):
        assert_clean_error(sphere_inproc("bench", *command), 2, option, fragment)


def test_vans1d_bench_reports_time_per_simulated_second_and_shares():
    result = sphere_inproc("bench", "vans1d", "--case", BEDLOAD, "--threads", "1", "--time", "0.002")
    assert result.code == 0, result.stdout + result.stderr
    assert re.search(r"threads 1: [0-9.]+ s per simulated second", result.stdout)
    for part in ("fluid forces", "averaging", "fluid resolution"):
        assert re.search(rf"{part} [0-9.]+ %", result.stdout), part


def test_compile_bench_times_each_thread_count_cold_then_cached(monkeypatch):
    """Each round times a fresh cache on each count, alternating: the child (the scene's first
    steps) runs on that many threads, once on the empty cache, then on the one it filled. The
    child is replaced by one that says what it was given (a cold compile takes 15-40 s)."""
    from sphere_cli.bench import compile as bench_compile

    calls = []

    def child(command, env, **kwargs):
        calls.append((env["NUMBA_NUM_THREADS"], env["NUMBA_CACHE_DIR"]))
        seconds = 10.0 * int(env["NUMBA_NUM_THREADS"]) + len(calls)
        return subprocess.CompletedProcess(command, 0, stdout=json.dumps({"seconds": seconds}) + "\n")

    monkeypatch.setattr(bench_compile.subprocess, "run", child)
    lines = []
    results = bench_compile.run_compile_benchmark(2, (1, 2), log=lines.append)
    assert [threads for threads, _ in calls] == ["1", "1", "2", "2"] * 2
    caches = [cache for _, cache in calls]
    assert caches[0] == caches[1] and len(set(caches[::2])) == 4  # cached after cold, then a new one
    assert results == {
        1: {"cold_seconds": [11.0, 15.0], "cached_seconds": [12.0, 16.0]},
        2: {"cold_seconds": [23.0, 27.0], "cached_seconds": [24.0, 28.0]},
    }
    assert "on 2 threads: cold 23.0 s, cached 24.00 s" in lines[1]


def test_help_of_every_benchmark():
    for name in ("dem", "fluid", "darcy", "vans1d", "grid", "compile"):
        result = sphere_inproc("bench", name, "--help")
        assert result.code == 0 and "Usage" in result.stdout, name


def test_ranks_bench_times_one_and_two_ranks_side_by_side(tmp_path, monkeypatch):
    # the settled bed goes to this test's own cache (settled once: 0.15 s of 64 spheres); the
    # ranks load the kernels this process has compiled
    monkeypatch.setenv("NUMBA_CACHE_DIR", numba.config.CACHE_DIR)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    result = sphere_inproc(
        "bench", "ranks", "--sizes", "64", "--ranks", "1,2", "--steps", "5", "--repeats", "1",
        "--rounds", "2", "--walls", "moving", "-o", tmp_path / "out",
    )  # fmt: skip
    assert result.code == 0, result.stdout + result.stderr
    report = json.loads((tmp_path / "out" / "ranks.json").read_text())
    one, two = report["rows"]
    assert (one["walls"], two["walls"]) == ("moving", "moving")
    assert (one["ranks"], two["ranks"]) == (1, 2) and len(two["seconds"]) == 2
    assert one["speedup_over_first"] == 1.0 and min(two["speedup_range"]) > 0
    assert two["particle_steps_per_second"] == 64 * 5 / statistics.median(two["seconds"])
    assert "N = 64, moving lid: 2 rank(s)" in result.stdout
