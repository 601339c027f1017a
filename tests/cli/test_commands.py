"""The commands on good input: validate, schema, run, inspect, resume and the wall-time budget."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
from cli_test_support import (
    FROM_FILE,
    TINY,
    TINY_END_STEP,
    TWO_SPHERES_CSV,
    assert_clean_error,
    edit,
    sphere,
    sphere_inproc,
)

from sphere_cli import api
from sphere_cli.runtime import parse_wall_time

CONFIGS = Path(__file__).parents[2] / "configs"

# --- validate and schema ---------------------------------------------------------------------------


def test_validate_prints_the_resolved_case_as_toml(tmp_path):
    case = tmp_path / "case.toml"
    case.write_text(TINY)
    result = sphere("validate", case)
    assert_clean_error(result, 0)
    assert result.stdout.startswith(f"# {case}: valid")
    assert "\n[simulation]\n" in result.stdout
    assert re.search(r"^dt_safety = 0\.08$", result.stdout, re.M)  # a default, filled in
    assert re.search(r"^\[particles\.radius\]\ndistribution = \"uniform\"$", result.stdout, re.M)
    assert re.search(r"^\[\[walls\]\]\nface = \"z-\"$", result.stdout, re.M)


@pytest.mark.parametrize("name", sorted(p.stem for p in CONFIGS.glob("*.toml")))
def test_what_validate_prints_runs_as_the_same_case(tmp_path, name):
    """Saved and validated again, the output of `sphere validate` is the same resolved case."""
    source = CONFIGS / f"{name}.toml"
    result = sphere_inproc("validate", source)
    assert_clean_error(result, 0)
    saved = tmp_path / f"{name}.toml"
    saved.write_text(result.stdout)
    for bed in CONFIGS.glob("*.csv"):  # the placement files (bedload beds), beside the case
        shutil.copy(bed, tmp_path)
    again = sphere_inproc("validate", saved, "--json")
    assert_clean_error(again, 0)
    assert json.loads(again.stdout) == api.validate(source)


def test_validate_json_fills_in_defaults(tmp_path):
    case = tmp_path / "case.toml"
    case.write_text(TINY)
    resolved = json.loads(sphere_inproc("validate", case, "--json").stdout)
    assert resolved["simulation"]["dt"] == "auto"
    assert resolved["simulation"]["dt_safety"] == 0.08
    assert resolved["particles"]["overlap_tolerance"] == 0.05
    assert resolved["particles"]["placement"] == {
        "method": "lattice",
        "spacing": 1.2,
        "jitter": 0.1,
        "region_lower": None,
        "region_upper": None,
    }
    assert resolved["contact"]["tangential_stiffness"] is None
    unset = ("velocity", "stress", "stress_amplitude", "frequency", "phase", "shear_axis", "shear_velocity")
    unset += ("shear_stress", "mass", "damping", "friction", "material", "rough")
    assert resolved["walls"] == [{"face": "z-", "mode": "fixed", **dict.fromkeys(unset)}]
    assert resolved["output"]["checkpoints"]["keep"] == 3
    assert resolved["domain"]["periodic"] == [False, False, False]


def test_validate_fills_in_the_default_tags(tmp_path):
    """`model`, `distribution` and `method` have declared defaults: a table without them uses them."""
    text = edit(TINY, 'model = "linear"\n', "")
    text = edit(
        text,
        'radius = { distribution = "uniform", min = 0.0008, max = 0.001 }',
        "radius = { value = 0.0009 }",
    )
    text = edit(text, 'placement = { method = "lattice" }', "placement = { spacing = 1.5 }")
    case = tmp_path / "case.toml"
    case.write_text(text)
    result = sphere_inproc("validate", case, "--json")
    assert_clean_error(result, 0)
    resolved = json.loads(result.stdout)
    assert resolved["contact"]["model"] == "linear"
    assert resolved["particles"]["radius"] == {"distribution": "fixed", "value": 0.0009}
    assert resolved["particles"]["placement"]["method"] == "lattice"
    assert resolved["particles"]["placement"]["spacing"] == 1.5


def test_validate_reads_the_placement_file_and_writes_nothing(tmp_path):
    """`validate` reads the placement file as `run` would (a missing one is reported, exit 66,
    before a batch job is queued), builds no scene and writes nothing."""
    case = tmp_path / "case.toml"
    case.write_text(FROM_FILE)
    assert_clean_error(sphere("validate", case, "--json", cwd=tmp_path), 66, "spheres.csv", "not found")
    (tmp_path / "spheres.csv").write_text(TWO_SPHERES_CSV)
    result = sphere("validate", case, "--json", cwd=tmp_path)
    assert_clean_error(result, 0)
    assert json.loads(result.stdout)["particles"]["placement"]["path"] == "spheres.csv"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["case.toml", "spheres.csv"]


def test_every_example_config_validates():
    configs = sorted(CONFIGS.glob("*.toml"))
    assert configs
    for case in configs:
        assert_clean_error(sphere_inproc("validate", case), 0)


def test_schema_is_json_schema_naming_the_sections():
    result = sphere("schema")
    assert_clean_error(result, 0)
    schema = json.loads(result.stdout)
    assert schema["type"] == "object"
    sections = {
        "title",
        "simulation",
        "domain",
        "particles",
        "contact",
        "materials",
        "walls",
        "stages",
        "fluid",
        "output",
    }
    assert set(schema["properties"]) == sections
    # particles and contact are required unless the case has a fluid (checked with the case, not
    # by the schema: a fluid-only scene has neither)
    assert set(schema["required"]) == {"simulation", "domain"}
    assert schema["additionalProperties"] is False  # typos are errors
    simulation = schema["$defs"]["Simulation"]
    assert "[s]" in simulation["properties"]["duration"]["description"]  # units in descriptions
    assert simulation["additionalProperties"] is False


# --- run -------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory) -> tuple[Path, object]:
    root = tmp_path_factory.mktemp("tiny")
    (root / "case.toml").write_text(TINY)
    result = sphere("run", "case.toml", "-o", "run", cwd=root)
    return root / "run", result


def test_run_writes_the_run_directory(tiny_run):
    run, result = tiny_run
    assert_clean_error(result, 0)
    assert f"step {TINY_END_STEP}" in result.stdout and "trajectory.xmf" in result.stdout
    for name in ("case.toml", "trajectory.h5", "trajectory.xmf", "status.json", "run.log"):
        assert (run / name).is_file(), name
    assert (run / "case.toml").read_text() == TINY
    status = json.loads((run / "status.json").read_text())
    assert status["state"] == "done"
    assert status["step"] == status["end_step"] == TINY_END_STEP
    checkpoints = sorted(p.name for p in (run / "checkpoints").iterdir())
    last = f"ckpt-{TINY_END_STEP:012d}.h5"
    assert checkpoints == ["ckpt-000000001700.h5", "ckpt-000000001750.h5", last]  # keep = 3
    assert (
        "trajectory.h5:/sphere/xdmf/particles/trajectory/position/00000000"
        in (run / "trajectory.xmf").read_text()
    )
    log = (run / "run.log").read_text()
    assert f"running from step 0 to {TINY_END_STEP}" in log and f"done at step {TINY_END_STEP}" in log


def test_run_without_output_uses_runs_case_name(tmp_path):
    (tmp_path / "mycase.toml").write_text(TINY)
    assert_clean_error(sphere_inproc("run", "mycase.toml", "-q", cwd=tmp_path), 0)
    assert (tmp_path / "runs" / "mycase" / "trajectory.h5").is_file()


def test_run_from_a_placement_file(tmp_path):
    (tmp_path / "case.toml").write_text(FROM_FILE)
    (tmp_path / "spheres.csv").write_text(TWO_SPHERES_CSV)
    assert_clean_error(sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path), 0)
    summary = json.loads(sphere_inproc("inspect", tmp_path / "out" / "trajectory.h5", "--json").stdout)
    assert summary["particles"] == 2


def test_a_single_particle_on_a_floor(tmp_path):
    """One particle has no pair limit: the wall gives dt = "auto" its limit."""
    (tmp_path / "case.toml").write_text(edit(TINY, "count = 20", "count = 1"))
    assert_clean_error(sphere("run", "case.toml", "-o", "out", "-q", cwd=tmp_path), 0)


# --- inspect ---------------------------------------------------------------------------------------


def test_inspect_run_directory(tiny_run):
    run, _ = tiny_run
    result = sphere("inspect", run)
    assert_clean_error(result, 0)
    assert "kind: run directory" in result.stdout and "state: done" in result.stdout
    assert f"file=ckpt-{TINY_END_STEP:012d}.h5, step={TINY_END_STEP}" in result.stdout
    summary = json.loads(sphere_inproc("inspect", run, "--json").stdout)
    assert summary["kind"] == "run directory"
    assert summary["status"]["state"] == "done"
    assert summary["trajectory"]["last_step"] == TINY_END_STEP
    assert [c["valid"] for c in summary["checkpoints"]] == [True, True, True]


def test_inspect_trajectory(tiny_run):
    run, _ = tiny_run
    text = sphere_inproc("inspect", run / "trajectory.h5")
    assert_clean_error(text, 0)
    assert "kind: trajectory" in text.stdout and "particles: 20" in text.stdout
    summary = json.loads(sphere_inproc("inspect", run / "trajectory.h5", "--json").stdout)
    assert summary["kind"] == "trajectory"
    assert summary["title"] == "tiny"
    assert summary["particles"] == 20
    assert summary["last_step"] == TINY_END_STEP
    assert summary["frames"] == 1 + TINY_END_STEP // 50 + 1  # start, every 50 steps, the end
    assert summary["contact_model"] == "linear" and summary["walls"] == ["z-"]
    assert summary["dt"] < summary["dt_limit"]
    assert "kinetic_energy" in summary["last_observables"]


def test_inspect_checkpoint(tiny_run):
    run, _ = tiny_run
    path = run / "checkpoints" / "ckpt-000000001750.h5"
    text = sphere_inproc("inspect", path)
    assert_clean_error(text, 0)
    assert "kind: checkpoint" in text.stdout and "step: 1750" in text.stdout
    summary = json.loads(sphere_inproc("inspect", path, "--json").stdout)
    assert summary["kind"] == "checkpoint"
    assert summary["valid"] is True
    assert summary["step"] == 1750
    assert summary["particles"] == 20
    assert summary["modules"] == ["neighbors", "particles", "walls"]


# --- wall-time budget and resume -------------------------------------------------------------------


def test_max_wall_time_zero_stops_then_resume_completes(tmp_path):
    (tmp_path / "case.toml").write_text(TINY)
    result = sphere("run", "case.toml", "-o", "run", "-q", "--max-wall-time", "0", cwd=tmp_path)
    assert_clean_error(result, 75, "stopped early", "sphere resume run")
    run = tmp_path / "run"
    status = json.loads((run / "status.json").read_text())
    assert status["state"] == "stopped" and status["step"] == 0
    assert [p.name for p in (run / "checkpoints").iterdir()] == ["ckpt-000000000000.h5"]

    result = sphere("resume", "run", "-q", cwd=tmp_path)
    assert_clean_error(result, 0)
    status = json.loads((run / "status.json").read_text())
    assert status["state"] == "done" and status["step"] == TINY_END_STEP
    assert "resuming from ckpt-000000000000.h5 (step 0)" in (run / "run.log").read_text()


def test_resume_until_extends_a_finished_run(tiny_run, tmp_path):
    run = tmp_path / "run"
    shutil.copytree(tiny_run[0], run)
    assert_clean_error(sphere_inproc("resume", run, "-q", "--until", "0.003"), 0)
    status = json.loads((run / "status.json").read_text())
    assert status["state"] == "done" and status["time"] >= 0.003


def test_max_wall_time_with_units_parses(tmp_path):
    (tmp_path / "case.toml").write_text(TINY)
    result = sphere_inproc("run", "case.toml", "-o", "run", "-q", "--max-wall-time", "2h", cwd=tmp_path)
    assert_clean_error(result, 0)


@pytest.mark.parametrize(
    ("text", "seconds"),
    [
        ("3600", 3600.0),
        ("90s", 90.0),
        ("45m", 2700.0),
        ("2h", 7200.0),
        ("1.5d", 129600.0),
        (" 0 ", 0.0),
        ("2h30m", 9000.0),
        ("1d12h", 129600.0),
        # SLURM's forms (sbatch --time)
        ("30:00", 1800.0),
        ("2:30:00", 9000.0),
        ("1-12:00:00", 129600.0),
        ("1-12", 129600.0),
        ("1-12:30", 131400.0),
    ],
)
def test_parse_wall_time(text, seconds):
    assert parse_wall_time(text) == seconds


@pytest.mark.parametrize("text", ["banana", "-1h", "2 hours", "1e3", "h", "", "1:2:3:4", "2h30", "1-", "::"])
def test_parse_wall_time_rejects(text):
    with pytest.raises(ValueError, match="expected a duration"):
        parse_wall_time(text)


def test_max_wall_time_banana_is_a_usage_error(tmp_path):
    (tmp_path / "case.toml").write_text(TINY)
    for command in (["run", "case.toml", "-o", "run"], ["resume", "run"]):
        result = sphere(*command, "--max-wall-time", "banana", cwd=tmp_path)
        assert_clean_error(result, 2, "banana")
    assert not (tmp_path / "run").exists()


@pytest.mark.parametrize("until", ["-1", "0", "nan", "inf", "soon"])
def test_until_must_be_a_positive_time(tmp_path, until):
    (tmp_path / "case.toml").write_text(TINY)
    for command in (["run", "case.toml", "-o", "run"], ["resume", "run"]):
        result = sphere_inproc(*command, "--until", until, cwd=tmp_path)
        assert_clean_error(result, 2, "--until")
    assert not (tmp_path / "run").exists()


def test_help_of_every_command():
    for command in ("run", "resume", "inspect", "validate", "schema", "plot", "bench", "verify"):
        for flag in ("--help", "-h"):
            result = sphere_inproc(command, flag)
            assert_clean_error(result, 0)
            assert "Usage" in result.stdout


def test_help_is_plain_text_with_flags_as_flags():
    """No markup eats bracketed text; a flag takes no value, so none is shown."""
    plot = sphere("plot", "--help").stdout
    assert "pip install 'sphere-cli[plot]'" in " ".join(plot.split())
    run = sphere("run", "-h").stdout
    assert "End time [s]" in run
    assert re.search(r"^\s+--overwrite\s+Replace", run, re.M), run
    assert re.search(r"^\s+-q, --quiet\s+No progress", run, re.M), run
    assert "<bool>" not in run and "╭" not in run


def test_version():
    result = sphere("--version")
    assert_clean_error(result, 0)
    assert re.fullmatch(r"sphere \d+\.\d+\.\d+\S*\n", result.stdout), result.stdout


def test_shell_completion_can_be_shown_and_installed():
    # typer finds the shell among the parent processes: run from bash, as a user would
    proc = subprocess.run(
        # a second command keeps bash from replacing itself with sphere (it would not be a parent)
        ["bash", "-c", f"{Path(sys.executable).parent / 'sphere'} --show-completion; exit $?"],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert "complete" in proc.stdout and "_SPHERE_COMPLETE" in proc.stdout
    assert "--install-completion" in sphere("-h").stdout


# --- what a batch job's log and monitor see ----------------------------------------------------------


def test_status_exists_while_the_scene_is_built(tmp_path, monkeypatch):
    """The run directory and status.json ("starting") exist before the scene is built and the
    kernels compiled, and the terminal says what is going on."""
    from sphere_cli.scene import builder as scene_module

    seen = {}
    real = scene_module.build_scene

    def watching(loaded, restart=None):
        status = tmp_path / "run" / "status.json"
        seen["status"] = json.loads(status.read_text()) if status.is_file() else None
        return real(loaded, restart)

    monkeypatch.setattr(api, "build_scene", watching)
    (tmp_path / "case.toml").write_text(TINY)
    result = sphere_inproc("run", "case.toml", "-o", "run", cwd=tmp_path)
    assert_clean_error(result, 0)
    assert seen["status"]["state"] == "starting" and "compiling" in seen["status"]["activity"]
    assert "[sphere] building the scene and compiling the kernels" in result.stderr


def test_a_case_refused_while_building_leaves_no_directory(tmp_path):
    text = edit(TINY, 'dt = "auto"', "dt = 1.0")  # above the stability limit: refused by the build
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("run", "case.toml", "-o", "run", "-q", cwd=tmp_path)
    assert_clean_error(result, 65, "stability limit")
    assert not (tmp_path / "run").exists()
    (tmp_path / "empty").mkdir()  # a directory the user made stays, empty
    result = sphere_inproc("run", "case.toml", "-o", "empty", "-q", cwd=tmp_path)
    assert_clean_error(result, 65)
    assert (tmp_path / "empty").is_dir() and not list((tmp_path / "empty").iterdir())


def test_the_rate_leaves_out_the_first_step():
    """The first step compiles the step's kernels: the rate and ETA count from its end."""
    from types import SimpleNamespace

    from sphere_cli.io.progress import Progress

    progress = Progress(None, 1000, 0, 1e-5, 10, 60.0, enabled=False, compiling=lambda: 0.0)
    scene = SimpleNamespace(state=SimpleNamespace(clock=SimpleNamespace(step=1, time=1e-5)))
    assert progress.info(scene, 30.0)["eta_seconds"] is None  # no rate before the first step ends
    progress.first_step_done(1)
    progress.rate_start = (1, progress.rate_start[1] - 2.0, 0.0)  # as if 2 s had passed since
    scene.state.clock.step = 201
    info = progress.info(scene, 32.0)
    assert info["steps_per_second"] == pytest.approx(100.0, rel=0.05)  # 200 steps in 2 s, not 201 in 32
    assert info["eta_seconds"] == pytest.approx(8.0, rel=0.05)


def test_the_rate_leaves_out_kernels_compiled_after_the_first_step():
    """A fluid's kernels compile at its first fluid step, hundreds of steps in: the seconds spent
    compiling (compile_lock.seconds_compiling) are left out of the rate and the ETA."""
    from types import SimpleNamespace

    from sphere_cli.io.progress import Progress

    compiled = [5.0]  # the scene's build compiled for 5 s before the loop
    progress = Progress(None, 1000, 0, 1e-5, 10, 60.0, enabled=False, compiling=lambda: compiled[0])
    scene = SimpleNamespace(state=SimpleNamespace(clock=SimpleNamespace(step=1, time=1e-5)))
    progress.first_step_done(1)
    first, then, _ = progress.rate_start
    progress.rate_start = (first, then - 32.0, compiled[0])  # 32 s since the first step ...
    compiled[0] += 30.0  # ... 30 of them compiling a fluid's kernels
    scene.state.clock.step = 201
    info = progress.info(scene, 33.0)
    assert info["steps_per_second"] == pytest.approx(100.0, rel=0.05)  # 200 steps in 2 s of stepping
    assert info["eta_seconds"] == pytest.approx(8.0, rel=0.05)
    assert info["compiling_seconds"] == pytest.approx(30.0)  # the loop's own, not the build's


def test_a_long_compile_inside_the_loop_gets_a_line_once():
    """A fluid's kernels compile at its first fluid step (half a minute on a first run) with the
    progress line silent: a compile in the loop lasting notice_seconds says so, once a run; one
    before the first step (the build's, announced already) or after close says nothing."""
    import io

    from numba import njit

    from sphere_cli import compile_lock
    from sphere_cli.io.progress import Progress

    def compile_one():
        @njit
        def kernel(x):
            return x * 3.0

        kernel(1.0)

    stream = io.StringIO()
    stream.isatty = lambda: False  # the batch log's line, not the terminal's bar
    progress = Progress(None, 1000, 0, 1e-5, 10, 60.0, stream=stream, compiling=lambda: 0.0)
    progress.notice_seconds = 0.0
    try:
        compile_one()  # before the first step
        assert stream.getvalue() == ""
        progress.first_step_done(1)
        for _ in range(3):  # each compile lasts well over the notice's 0 s
            compile_one()
    finally:
        progress.close()
    assert stream.getvalue().count("[sphere] compiling kernels") == 1
    assert progress._compile_watch not in compile_lock.watchers
    compile_one()
    assert stream.getvalue().count("compiling kernels") == 1


def test_the_closing_line_says_how_much_of_a_run_was_compiling(tmp_path, capsys):
    """A first run's closing line says how long it compiled, so that it does not look that slow;
    a run from the cache says nothing of it."""
    from sphere_cli.cli import _report

    first = api.RunResult(tmp_path, "done", 3474, 0.002, 32.2, 2.0e4, 34.0, compiling_seconds=31.5)
    _report(first)
    assert "in 32.2 s (31.5 s of it compiling kernels, cached for later runs)" in capsys.readouterr().out
    _report(api.RunResult(tmp_path, "done", 3474, 0.002, 0.4, 2.0e6, 8685.0, compiling_seconds=0.01))
    assert "compiling" not in capsys.readouterr().out


def test_the_closing_figures_count_the_scene_s_build_and_its_compiles(tmp_path, monkeypatch):
    """A first run compiles much of its kernels while its scene is built (the pair sweeps, a
    helper's kernels: 23 of the 47 s of the demo's first run on two threads), before the loop
    starts: the closing line's wall time and its share compiling count from the command's start
    (they said 22.9 s, 22.8 s of it compiling, for that run of 46.9 s). Here the build is made
    to take 0.5 s more, counted as compiling; a resume likewise."""
    from sphere_cli import compile_lock

    real = api.build_scene

    def slow_build(*args, **kwargs):
        import time

        time.sleep(0.5)
        monkeypatch.setattr(compile_lock, "_seconds", compile_lock._seconds + 0.5)
        return real(*args, **kwargs)

    monkeypatch.setattr(api, "build_scene", slow_build)
    case = tmp_path / "case.toml"
    case.write_text(TINY)
    ran = api.run(case, tmp_path / "run", until=0.0001)
    assert ran.wall_seconds >= 0.5 and ran.compiling_seconds >= 0.5
    resumed = api.resume(tmp_path / "run", until=0.0002)
    assert resumed.wall_seconds >= 0.5 and resumed.compiling_seconds >= 0.5
    assert "s of it compiling kernels" in (tmp_path / "run" / "run.log").read_text()


def test_the_time_spent_compiling_is_counted_once_and_in_full():
    """compile_lock.seconds_compiling: a kernel's compile, its callees' nested in it, counted once;
    a kernel already compiled adds nothing."""
    import time

    from numba import njit

    from sphere_cli.compile_lock import seconds_compiling

    @njit
    def callee(x):
        return x + 1.0

    @njit
    def caller(x):
        return callee(x) * 2.0

    before = seconds_compiling()
    started = time.monotonic()
    caller(1.0)
    took = time.monotonic() - started
    spent = seconds_compiling() - before
    assert 0.5 * took < spent <= took  # nearly all of the first call is compiling, counted once
    again = seconds_compiling()
    caller(2.0)
    assert seconds_compiling() == again


def test_a_run_too_short_to_time_says_so_rather_than_a_rate_of_zero(tmp_path):
    """The rate leaves out the first step (it compiles the kernels): a run of one step printed
    "0 steps/s" (and run.log "0 steps/s, 0 particle-steps/s"), which reads as a hung run."""
    (tmp_path / "case.toml").write_text(TINY)
    result = sphere_inproc("run", "case.toml", "-o", "out", "--until", "1e-9", cwd=tmp_path)
    assert_clean_error(result, 0)
    assert "(step 1)" in result.stdout and "too few steps to time" in result.stdout, result.stdout
    assert "steps/s" not in result.stdout
    assert "too few steps to time" in (tmp_path / "out" / "run.log").read_text()
    longer = sphere_inproc("run", "case.toml", "-o", "longer", "--until", "1e-4", cwd=tmp_path)
    assert re.search(r"\(step \d+\) in [0-9.]+ s, [0-9.]+ M particle-steps/s", longer.stdout), longer.stdout
