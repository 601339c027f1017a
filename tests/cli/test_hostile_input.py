"""Hostile case files: sizes that cannot fit, numbers at the edge of float64 and int64, nesting,
paths and files the system cannot use, and inputs made to exhaust the checks themselves. Each is
refused with a clean error (exit 65 for the case, 66 for the input file) naming the key, or, where
allowed but probably not meant, warned of naming the key.

The memory the machine has is replaced by SPHERE_MEMORY_GIB where a test needs a known limit;
the subprocess time limits bound what would otherwise hang (they are not timings of speed).
"""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest
from cli_test_support import (
    FROM_FILE,
    NAVIER_STOKES_SCENE,
    TINY,
    TWO_SPHERES_CSV,
    assert_clean_error,
    edit,
    line_of,
    sphere,
    sphere_inproc,
)

# --- sizes that cannot fit -----------------------------------------------------------------------
# (id, [(old, new), ...] edits of TINY, key named, fragments of the message)
TOO_BIG = [
    (
        "a-trillion-particles",
        [("count = 20", "count = 1000000000000")],
        "particles.count",
        ["1e+12 particles", "GiB of memory"],
    ),
    (
        "count-at-int64-max",
        [("count = 20", "count = 9223372036854775807")],
        "particles.count",
        ["GiB of memory"],
    ),
    (
        "count-beyond-int64",
        [("count = 20", "count = 9223372036854775808")],
        "particles.count",
        ["64-bit"],
    ),
    (
        "a-billion-in-a-large-box",
        [
            ("count = 20", "count = 1000000000"),
            ("upper = [0.01, 0.01, 0.02]", "upper = [300.0, 300.0, 600.0]"),
        ],
        "particles.count",
        ["1e+09 particles", "GiB of memory"],
    ),
    (
        "random-placement-of-ten-million",
        [
            ("count = 20", "count = 10000000"),
            ("upper = [0.01, 0.01, 0.02]", "upper = [3.0, 3.0, 6.0]"),
            ('method = "lattice"', 'method = "random"'),
        ],
        "particles.placement",
        ["candidate positions", "GiB of memory"],
    ),
    (
        "more-spheres-than-the-box-holds",
        [("count = 20", "count = 5000")],
        "particles.count",
        ["more than the", "placement region holds"],
    ),
    (
        "lognormal-kept-range-too-narrow",
        [
            (
                'radius = { distribution = "uniform", min = 0.0008, max = 0.001 }',
                'radius = { distribution = "lognormal", median = 0.0009, sigma = 2.0, '
                "min = 0.0009, max = 0.00090000001 }",
            )
        ],
        "particles.radius",
        ["draws"],
    ),
]


def _edited(edits) -> str:
    text = TINY
    for old, new in edits:
        text = edit(text, old, new)
    return text


@pytest.mark.parametrize("edits, key, fragments", [c[1:] for c in TOO_BIG], ids=[c[0] for c in TOO_BIG])
def test_a_scene_that_cannot_fit_is_refused_by_validate_and_run(tmp_path, edits, key, fragments):
    text = _edited(edits)
    (tmp_path / "case.toml").write_text(text)
    line = line_of(text, key.split(".")[-1].split("[")[0] + " =")
    for command in (("validate", "case.toml"), ("run", "case.toml", "-o", "out", "-q")):
        result = sphere_inproc(*command, cwd=tmp_path)
        assert_clean_error(result, 65, f"case.toml:{line}: {key}", *fragments)
    assert not (tmp_path / "out").exists(), "a refused case must not leave a run directory"


def _capped_run(tmp_path, text: str) -> subprocess.CompletedProcess:
    """`sphere run` of `text` in a fresh interpreter whose address space is capped at 4 GiB."""
    (tmp_path / "case.toml").write_text(text)
    cap = (
        "import resource, runpy, sys; resource.setrlimit(resource.RLIMIT_AS, (4 << 30, 4 << 30)); "
        "sys.argv = ['sphere'] + sys.argv[1:]; runpy.run_module('sphere_cli.cli', run_name='__main__')"
    )
    return subprocess.run(
        [sys.executable, "-c", cap, "run", "case.toml", "-o", "out", "-q"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=300,
    )


def test_a_scene_that_cannot_fit_is_refused_in_a_real_process_before_allocating(tmp_path):
    """A scene that asked for its 1000 GiB before being refused would end in a MemoryError in a
    process capped at 4 GiB, not in this message."""
    proc = _capped_run(tmp_path, _edited(TOO_BIG[3][1]))
    assert proc.returncode == 65, proc.stderr
    assert "particles.count" in proc.stderr and "GiB of memory" in proc.stderr
    assert "Traceback" not in proc.stderr and "MemoryError" not in proc.stderr
    assert not (tmp_path / "out").exists()


def test_a_box_written_in_millimetres_runs_in_little_memory(tmp_path):
    """20 spheres of 1 mm in a 10 x 10 x 20 m box (millimetres written as metres): 10^11 cells of
    the neighbour search, which took 28 000 GiB as a table of every cell and was refused; only
    the occupied cells are listed now (physics/neighbors.py), so it runs in 4 GiB."""
    proc = _capped_run(tmp_path, _edited([("upper = [0.01, 0.01, 0.02]", "upper = [10.0, 10.0, 20.0]")]))
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "out" / "trajectory.h5").is_file()


def test_the_memory_limit_can_be_set_for_another_machine(tmp_path, monkeypatch):
    # TINY's 20 particles and its neighbour grid need ~20 kB: under 10 kB they cannot fit
    (tmp_path / "case.toml").write_text(TINY)
    monkeypatch.setenv("SPHERE_MEMORY_GIB", str(1e4 / 2**30))
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert_clean_error(result, 65, "particles.count", "SPHERE_MEMORY_GIB = ")
    monkeypatch.setenv("SPHERE_MEMORY_GIB", "1")
    assert sphere_inproc("validate", "case.toml", cwd=tmp_path).code == 0


@pytest.mark.parametrize("value", ["lots", "0", "-3", "nan", "inf"])
def test_a_bad_memory_limit_is_a_usage_error(tmp_path, monkeypatch, value):
    (tmp_path / "case.toml").write_text(TINY)
    monkeypatch.setenv("SPHERE_MEMORY_GIB", value)
    assert_clean_error(sphere_inproc("validate", "case.toml", cwd=tmp_path), 2, "SPHERE_MEMORY_GIB")


def test_particles_from_a_file_are_counted_once_read(tmp_path, monkeypatch):
    (tmp_path / "case.toml").write_text(FROM_FILE)
    (tmp_path / "spheres.csv").write_text(TWO_SPHERES_CSV)
    monkeypatch.setenv("SPHERE_MEMORY_GIB", str(1e3 / 2**30))  # less than two particles' 2 kB
    for command in (("validate", "case.toml"), ("run", "case.toml", "-o", "out", "-q")):  # both read it
        result = sphere_inproc(*command, cwd=tmp_path)
        assert_clean_error(result, 65, "particles.placement.path", "2 particles", "GiB of memory")
    assert not (tmp_path / "out").exists()


FLUID_TOO_BIG = [
    ("grid = { cells = [4, 4, 8] }", "grid = { cells = [100000, 100000, 100000] }", "fluid.grid.cells"),
    ("grid = { cells = [4, 4, 8] }", "grid = { cell_size = 1e-300 }", "fluid.grid.cell_size"),
]


@pytest.mark.parametrize("old, new, key", FLUID_TOO_BIG, ids=["cells", "cell_size"])
def test_a_fluid_grid_that_cannot_fit_is_refused(tmp_path, old, new, key):
    text = edit(NAVIER_STOKES_SCENE, old, new)
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert_clean_error(result, 65, f"case.toml:{line_of(text, 'grid =')}: {key}", "GiB of memory")


def test_a_fluid_column_that_cannot_fit_is_refused_with_particles_from_a_file(tmp_path):
    text = FROM_FILE + '\n[fluid]\nmodel = "vans1d"\nsurface = 0.009\ncells = 1000000000000\n'
    (tmp_path / "case.toml").write_text(text)
    (tmp_path / "spheres.csv").write_text(TWO_SPHERES_CSV)
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert_clean_error(result, 65, f"case.toml:{line_of(text, 'cells =')}: fluid.cells", "GiB of memory")


# --- numbers at the edge of float64 ----------------------------------------------------------------


def test_a_subnormal_dt_is_refused(tmp_path):
    text = edit(TINY, 'dt = "auto"', "dt = 5e-324")
    (tmp_path / "case.toml").write_text(text)
    for command in (("validate", "case.toml"), ("run", "case.toml", "-o", "out", "-q")):
        result = sphere_inproc(*command, cwd=tmp_path)
        assert_clean_error(result, 65, f"case.toml:{line_of(text, 'dt =')}: simulation.dt", "2^53")


@pytest.mark.parametrize(
    "old, new",
    [("density = 2500.0", "density = 1e-308"), ("normal_stiffness = 1.0e4", "normal_stiffness = 1e308")],
    ids=["density", "stiffness"],
)
def test_an_auto_dt_that_underflows_is_refused_without_numpy_warnings(tmp_path, old, new):
    text = edit(TINY, old, new)
    (tmp_path / "case.toml").write_text(text)
    result = sphere("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    if "density" in new:  # its masses, 3e-317 kg, have no finite inverse: refused first
        assert_clean_error(result, 65, "particles.density", "mass of 3.3", "densities this small")
    else:
        assert_clean_error(result, 65, "simulation.dt", '"auto" gives 0 s')
    assert "Warning" not in result.stderr, result.stderr
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("radius", ["1e-300", "1e-120"])
def test_radii_whose_mass_underflows_are_refused_naming_the_key(tmp_path, radius):
    """r^3 and m r^2 underflow to 0 (and 1/m to inf): a ZeroDivisionError traceback before;
    refused with the particle, its mass and the key that sets the radii, by validate and run."""
    text = edit(TINY, "min = 0.0008, max = 0.001", f"min = {radius}, max = {radius}")
    (tmp_path / "case.toml").write_text(text)
    for command in (("validate", "case.toml"), ("run", "case.toml", "-o", "out", "-q")):
        result = sphere_inproc(*command, cwd=tmp_path)
        where = f"case.toml:{line_of(text, 'radius =')}: particles.radius"
        assert_clean_error(result, 65, where, "mass of 0 kg", "radii this small")
    assert not (tmp_path / "out").exists()


def test_radii_of_a_placement_file_whose_mass_underflows_are_refused_naming_the_file(tmp_path):
    (tmp_path / "case.toml").write_text(FROM_FILE)
    (tmp_path / "spheres.csv").write_text("x,y,z,r\n0.003,0.005,0.005,1e-300\n")
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert_clean_error(result, 65, "particles.placement.path", "particle 0 (r = 1e-300 m", "mass of 0 kg")


def test_a_lattice_of_tiny_spacing_counts_its_sites_without_overflow(tmp_path):
    """1e-60 m spheres in a centimetre box: 1e58 sites along each axis, whose product overflowed
    int64 into a refusal saying the lattice 'holds only -9223372036854775807 sites'; the lattice
    holds them, and what stops the case is its step (auto gives 0 s)."""
    text = edit(TINY, "min = 0.0008, max = 0.001", "min = 1e-60, max = 1e-60")
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert_clean_error(result, 65, "simulation.dt", '"auto" gives 0 s')
    assert "sites" not in result.stderr, result.stderr


def test_a_duration_beyond_float64_is_refused(tmp_path):
    text = edit(TINY, "duration = 0.002", "duration = 1e400")
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert_clean_error(result, 65, f"case.toml:{line_of(text, 'duration =')}: simulation.duration", "finite")


def test_a_dt_of_hundreds_of_digits_is_refused(tmp_path):
    text = edit(TINY, 'dt = "auto"', "dt = 1" + "0" * 400)
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert_clean_error(result, 65, "simulation.dt")


# --- the case file itself --------------------------------------------------------------------------


@pytest.mark.parametrize("depth", [100, 1000], ids=["beyond-sphere", "beyond-the-parser"])
def test_deep_nesting_is_refused(tmp_path, depth):
    (tmp_path / "case.toml").write_text(TINY + "deep = " + "[" * depth + "]" * depth + "\n")
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert_clean_error(result, 65, "case.toml", "nested")


def test_a_placement_path_longer_than_the_system_allows(tmp_path):
    text = FROM_FILE.replace("spheres.csv", "a" * 5000 + ".csv")
    (tmp_path / "case.toml").write_text(text)
    for command in (("validate", "case.toml"), ("run", "case.toml", "-o", "out", "-q")):
        result = sphere_inproc(*command, cwd=tmp_path)
        assert_clean_error(
            result, 65, f"case.toml:{line_of(text, 'path =')}: particles.placement.path", "bytes"
        )


def test_a_placement_path_holding_nul(tmp_path):
    text = FROM_FILE.replace("spheres.csv", "spheres\\u0000.csv")
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert_clean_error(result, 65, "particles.placement.path", "NUL")


def test_an_endless_device_is_not_read(tmp_path):
    result = sphere("validate", "/dev/zero", cwd=tmp_path, timeout=60)
    assert_clean_error(result, 66, "/dev/zero", "character device")


def test_a_named_pipe_is_not_opened(tmp_path):
    os.mkfifo(tmp_path / "case.toml")  # opening it would block until a writer came
    result = sphere("validate", "case.toml", cwd=tmp_path, timeout=60)
    assert_clean_error(result, 66, "case.toml", "named pipe")


def test_a_case_file_over_the_size_limit(tmp_path):
    (tmp_path / "case.toml").write_text(TINY + "#" * (2 << 20))
    assert_clean_error(sphere_inproc("validate", "case.toml", cwd=tmp_path), 65, "case.toml", "MiB")


def test_ten_thousand_walls_are_refused_by_count(tmp_path):
    (tmp_path / "case.toml").write_text(TINY + '[[walls]]\nface = "z+"\n' * 10_000)
    result = sphere("validate", "case.toml", cwd=tmp_path, timeout=60)
    assert_clean_error(result, 65, "walls", "10001 entries; at most 6")


def test_ten_thousand_stage_walls_are_refused_by_count(tmp_path):
    (tmp_path / "case.toml").write_text(
        TINY + "[[stages]]\nduration = 0.001\n" + '[[stages.walls]]\nface = "z-"\n' * 10_000
    )
    result = sphere("validate", "case.toml", cwd=tmp_path, timeout=60)
    assert_clean_error(result, 65, "stages[0].walls", "at most 6")


def test_many_errors_are_counted_not_all_listed(tmp_path):
    """20 000 stages of negative duration: validation stays linear in the input (a
    quadratic check would outlast the time limit) and reports the first errors."""
    stages = "".join(f'[[stages]]\nname = "s{i}"\nduration = -1.0\n' for i in range(20_000))
    (tmp_path / "case.toml").write_text(TINY + stages)
    result = sphere("validate", "case.toml", cwd=tmp_path, timeout=120)
    assert result.code == 65 and "Traceback" not in result.stderr, result.stderr
    assert "stages[0].duration" in result.stderr
    assert re.search(r"\.\.\. and \d+ more errors", result.stderr), result.stderr
    assert len(result.stderr.splitlines()) < 30


# --- allowed, but probably not meant: warned ---------------------------------------------------------


def test_a_fluid_that_drives_auto_dt_down_is_warned_of(tmp_path):
    """A viscosity of 1e6 Pa s (kinematic 1e3 m^2/s, a unit slip) makes the fluid's limit some
    1e5 times below the particles': the run goes ahead, with the key and the dt named."""
    text = edit(NAVIER_STOKES_SCENE, 'model = "navier-stokes"', 'model = "navier-stokes"\nviscosity = 1.0e6')
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", "--until", "1e-11", cwd=tmp_path)
    assert result.code == 0, result.stderr
    warning = next(line for line in result.stderr.splitlines() if line.startswith("sphere: warning:"))
    assert "simulation.dt" in warning and "fluid.viscosity = 1e+06 Pa s" in warning, warning
    dt = float(re.search(r"gives ([0-9.e+-]+) s", warning).group(1))
    assert 0 < dt < 1e-10, warning


def test_a_plain_viscous_fluid_is_not_warned_of(tmp_path):
    (tmp_path / "case.toml").write_text(NAVIER_STOKES_SCENE)
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", "--until", "1e-5", cwd=tmp_path)
    assert result.code == 0 and "warning" not in result.stderr, result.stderr


def test_a_run_of_billions_of_steps_is_warned_of(tmp_path):
    text = edit(edit(TINY, 'dt = "auto"', "dt = 1e-9"), "duration = 0.002", "duration = 10.0")
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert result.code == 0
    assert f"case.toml:{line_of(text, 'dt =')}: simulation.dt = 1e-09" in result.stderr, result.stderr
    assert "1e+10 steps" in result.stderr
