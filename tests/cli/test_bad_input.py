"""Every kind of bad input gets a short message naming the TOML key and line (or the file),
the exit code of the design guide (§6), and no traceback.

Exit codes: 2 usage; 65 bad case file; 66 missing input; 74 I/O failure; 78 resume refused.
Checks that need no scene run in-process (CliRunner); the rest, and a sample of the first kind,
run the real CLI in a subprocess.
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from cli_test_support import (
    FROM_FILE,
    TINY,
    TINY_END_STEP,
    TWO_SPHERES_CSV,
    assert_clean_error,
    edit,
    line_of,
    sphere,
    sphere_inproc,
)

from sphere_cli import api
from sphere_cli.errors import UsageError
from sphere_cli.runtime import refuse_many_ranks

# --- the case file alone ------------------------------------------------------------------------
# (id, text to replace, replacement, key named, text on the line named, other fragments)
CASE_ERRORS = [
    ("typo-top-level", 'title = "tiny"', 'titel = "tiny"', "titel", "titel", ["unknown key"]),
    (
        "typo-nested",
        'dt = "auto"',
        'dt = "auto"\ndt_safty = 0.2',
        "simulation.dt_safty",
        "dt_safty",
        ["unknown key"],
    ),
    (
        "typo-inline-table",
        "min = 0.0008, max = 0.001",
        "min = 0.0008, mx = 0.001",
        "particles.radius.mx",
        "radius =",
        ["unknown key"],
    ),
    ("typo-array-of-tables", 'face = "z-"', 'fase = "z-"', "walls[0].fase", "fase", ["unknown key"]),
    (
        "missing-required-key",
        "duration = 0.002\n",
        "",
        "simulation.duration",
        "[simulation]",
        ["required key is missing"],
    ),
    (
        "wrong-type-string-for-int",
        "count = 20",
        'count = "many"',
        "particles.count",
        "count =",
        ["valid integer"],
    ),
    (
        "wrong-type-bool-for-int",
        "count = 20",
        "count = true",
        "particles.count",
        "count =",
        ["valid integer"],
    ),
    (
        "wrong-type-string-for-float",
        "density = 2500.0",
        'density = "2500"',
        "particles.density",
        "density =",
        ["valid number"],
    ),
    (
        "wrong-type-number-for-flag",
        "upper = [0.01, 0.01, 0.02]",
        "upper = [0.01, 0.01, 0.02]\nperiodic = [0, 0, 0]",
        "domain.periodic[0]",
        "periodic =",
        ["boolean"],
    ),
    (
        "negative-radius",
        "min = 0.0008",
        "min = -0.0008",
        "particles.radius.min",
        "radius =",
        ["greater than 0"],
    ),
    (
        "negative-density",
        "density = 2500.0",
        "density = -2500.0",
        "particles.density",
        "density =",
        ["greater than 0"],
    ),
    (
        "zero-density",
        "density = 2500.0",
        "density = 0.0",
        "particles.density",
        "density =",
        ["greater than 0"],
    ),
    (
        "infinite-duration",
        "duration = 0.002",
        "duration = inf",
        "simulation.duration",
        "duration =",
        ["finite"],
    ),
    (
        "box-smaller-than-particle",
        "upper = [0.01, 0.01, 0.02]",
        "upper = [0.001, 0.01, 0.02]",
        "domain.upper",
        "upper =",
        ["smaller than the largest particle diameter 0.002 m"],
    ),
    (
        "periodic-axis-too-short",
        "upper = [0.01, 0.01, 0.02]",
        "upper = [0.003, 0.01, 0.02]\nperiodic = [true, false, false]",
        "domain.periodic",
        "periodic =",
        ["two largest diameters"],
    ),
    (
        "periodic-axis-with-wall",
        "upper = [0.01, 0.01, 0.02]",
        "upper = [0.01, 0.01, 0.02]\nperiodic = [false, false, true]",
        "walls[0].face",
        'face = "z-"',
        ["periodic", "cannot have a wall"],
    ),
    (
        "duplicate-wall-face",
        '[[walls]]\nface = "z-"',
        '[[walls]]\nface = "z-"\n\n[[walls]]\nface = "z-"  # twice',
        "walls[1].face",
        "# twice",
        ["walls[0] is already on this face"],
    ),
    ("unknown-wall-face", 'face = "z-"', 'face = "top"', "walls[0].face", "face =", ['"top"']),
    (
        "unknown-contact-model",
        'model = "linear"',
        'model = "hertz"',
        "contact.model",
        "model =",
        ['"hertz"', "expected one of", '"linear"'],
    ),
    (
        "unknown-radius-distribution",
        'distribution = "uniform"',
        'distribution = "gaussian"',
        "particles.radius.distribution",
        "radius =",
        ['"gaussian"', "expected one of", '"fixed"', '"uniform"', '"lognormal"', '"bimodal"'],
    ),
    (
        "unknown-placement-method",
        'method = "lattice"',
        'method = "poisson"',
        "particles.placement.method",
        "placement =",
        ['"poisson"', "expected one of", '"lattice"', '"random"', '"file"'],
    ),
    (
        "region-outside-box",
        'placement = { method = "lattice" }',
        'placement = { method = "lattice", region_upper = [0.02, 0.01, 0.01] }',
        "particles.placement.region_upper",
        "placement =",
        ["inside the domain box"],
    ),
    (
        "unknown-output-field",
        "[output.frames]",
        '[output]\nfields = ["pressure"]\n\n[output.frames]',
        "output.fields[0]",
        "fields =",
        ['"pressure"'],
    ),
    (
        "dt-not-a-number",
        'dt = "auto"',
        'dt = "fast"',
        "simulation.dt",
        "dt =",
        ['"fast"', 'positive number of seconds or "auto"'],
    ),
    (
        "dt-negative",
        'dt = "auto"',
        "dt = -1e-6",
        "simulation.dt",
        "dt =",
        ['positive number of seconds or "auto"'],
    ),
    ("dt-zero", 'dt = "auto"', "dt = 0.0", "simulation.dt", "dt =", ['positive number of seconds or "auto"']),
]


@pytest.mark.parametrize(
    ("old", "new", "key", "marker", "fragments"),
    [c[1:] for c in CASE_ERRORS],
    ids=[c[0] for c in CASE_ERRORS],
)
def test_case_file_error_names_key_and_line(tmp_path, old, new, key, marker, fragments):
    text = edit(TINY, old, new)
    case = tmp_path / "case.toml"
    case.write_text(text)
    result = sphere_inproc("validate", case)
    assert_clean_error(result, 65, key, f"case.toml:{line_of(text, marker)}:", *fragments)


SUBPROCESS_SAMPLE = [
    "typo-top-level",
    "negative-radius",
    "periodic-axis-with-wall",
    "unknown-contact-model",
    "dt-not-a-number",
]


@pytest.mark.parametrize("case_id", SUBPROCESS_SAMPLE)
def test_case_file_error_from_run_in_subprocess_writes_nothing(tmp_path, case_id):
    _, old, new, key, marker, _ = next(c for c in CASE_ERRORS if c[0] == case_id)
    text = edit(TINY, old, new)
    (tmp_path / "case.toml").write_text(text)
    result = sphere("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(result, 65, key, f"case.toml:{line_of(text, marker)}:")
    assert not (tmp_path / "out").exists(), "a refused case must not leave a run directory"


def test_toml_syntax_error_names_line(tmp_path):
    text = edit(TINY, 'dt = "auto"', 'dt = "auto')
    (tmp_path / "case.toml").write_text(text)
    result = sphere("validate", "case.toml", cwd=tmp_path)
    assert_clean_error(result, 65, f"case.toml:{line_of(text, 'dt =')}:", "not valid TOML")


def test_several_errors_are_reported_together(tmp_path):
    text = edit(edit(TINY, "density = 2500.0", "density = -1.0"), 'title = "tiny"', 'titel = "tiny"')
    case = tmp_path / "case.toml"
    case.write_text(text)
    result = sphere_inproc("validate", case)
    assert_clean_error(
        result,
        65,
        f"case.toml:{line_of(text, 'titel')}: titel",
        f"case.toml:{line_of(text, 'density')}: particles.density",
    )


def test_missing_case_file(tmp_path):
    for command in ("validate", "run"):
        result = sphere(command, "nowhere.toml", cwd=tmp_path)
        assert_clean_error(result, 66, "nowhere.toml", "not found")


def test_case_file_that_is_a_directory(tmp_path):
    (tmp_path / "case.toml").mkdir()
    assert_clean_error(sphere_inproc("validate", tmp_path / "case.toml"), 66, "case.toml")


def test_case_file_not_utf8(tmp_path):
    case = tmp_path / "case.toml"
    case.write_bytes(TINY.replace("tiny", "t\xe9").encode("latin-1"))
    assert_clean_error(sphere_inproc("validate", case), 65, "case.toml", "UTF-8")


def test_a_byte_order_mark_is_read_past(tmp_path):
    """Windows editors and Excel's "CSV UTF-8" begin a file with a byte-order mark: the case
    was "not valid TOML: Invalid statement (column 1)" and the placement file's header began
    with "\ufeffx", "must name columns x, y, z"; both read as without it now."""
    text = 'title = "caf\u00e9"\n' + FROM_FILE
    (tmp_path / "case.toml").write_bytes(b"\xef\xbb\xbf" + text.encode())
    (tmp_path / "spheres.csv").write_bytes(b"\xef\xbb\xbf" + TWO_SPHERES_CSV.encode())
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert result.code == 0, result.stderr
    assert 'title = "caf\u00e9"' in result.stdout


# --- errors found while building the scene --------------------------------------------------------


def test_dt_above_stability_limit_names_the_limit(tmp_path):
    text = edit(TINY, 'dt = "auto"', "dt = 1e-3")
    (tmp_path / "case.toml").write_text(text)
    result = sphere("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(result, 65, "simulation.dt", f"case.toml:{line_of(text, 'dt =')}:", "stability limit")
    limit = float(re.search(r"stability limit ([0-9.eE+-]+) s", result.stderr).group(1))
    assert 0 < limit < 1e-3
    assert not (tmp_path / "out").exists()


def test_lattice_too_small_for_the_count(tmp_path):
    # 300 spheres would fit the box at the densest packing (691), but not its 250 lattice sites
    text = edit(TINY, "count = 20", "count = 300")
    (tmp_path / "case.toml").write_text(text)
    for command in (("validate", "case.toml"), ("run", "case.toml", "-o", "out", "-q")):  # alike
        result = sphere_inproc(*command, cwd=tmp_path)
        assert_clean_error(
            result, 65, "particles.count", f"case.toml:{line_of(text, 'count =')}:", "lattice", "holds only"
        )


def test_random_insertion_that_cannot_fit_the_count(tmp_path):
    text = edit(TINY, "count = 20", "count = 500")
    text = edit(text, 'method = "lattice"', 'method = "random", max_attempts = 5')
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(
        result,
        65,
        "particles.placement",
        f"case.toml:{line_of(text, 'placement =')}:",
        "random insertion placed only",
    )


def _file_case(tmp_path: Path, csv: str | None, case_text: str = FROM_FILE) -> Path:
    (tmp_path / "case.toml").write_text(case_text)
    if csv is not None:
        (tmp_path / "spheres.csv").write_text(csv)
    return tmp_path / "case.toml"


def test_initial_overlap_beyond_tolerance(tmp_path):
    text = edit(FROM_FILE, "density = 2500.0", "density = 2500.0\noverlap_tolerance = 0.05")
    # centres 1.9 mm apart with radii 1 mm: overlap 0.1 of the radius, tolerance 0.05
    _file_case(tmp_path, "x,y,z,r\n0.004,0.005,0.005,0.001\n0.0059,0.005,0.005,0.001\n", text)
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(
        result,
        65,
        "particles.overlap_tolerance",
        f"case.toml:{line_of(text, 'overlap_tolerance')}:",
        "particles 0 and 1",
        "overlapping",
    )


def test_initial_overlap_within_tolerance_runs(tmp_path):
    # overlap 0.01 of the radius, below the default tolerance of 0.05
    _file_case(tmp_path, "x,y,z,r\n0.004,0.005,0.005,0.001\n0.00599,0.005,0.005,0.001\n")
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(result, 0)


def test_particle_outside_the_box_from_file(tmp_path):
    _file_case(tmp_path, "x,y,z,r\n0.005,0.005,0.005,0.001\n0.02,0.005,0.005,0.001\n")
    for command in (("run", "case.toml", "-o", "out", "-q"), ("validate", "case.toml")):
        result = sphere_inproc(*command, cwd=tmp_path)
        assert_clean_error(
            result,
            65,
            "particles.placement",
            f"case.toml:{line_of(FROM_FILE, 'placement =')}:",
            "particle 1",
            "outside the box along x",
        )


def test_missing_placement_file(tmp_path):
    _file_case(tmp_path, None)
    result = sphere("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(
        result,
        66,
        "particles.placement.path",
        f"case.toml:{line_of(FROM_FILE, 'placement =')}:",
        "spheres.csv",
        "not found",
    )
    assert not (tmp_path / "out").exists()
    # validate, before a batch job is queued, finds it missing too (it read no placement file)
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert_clean_error(result, 66, "particles.placement.path", "spheres.csv", "not found")


@pytest.mark.parametrize(
    ("csv", "fragment"),
    [
        ("x,y,z,r\n0.005,0.005,0.005,0.001\n0.002,0.002\n", "spheres.csv:3: 2 fields, but"),
        ("a,b,c\n1,2,3\n", "must name columns x, y, z"),
        ("x,y,z,r\n", "N >= 1"),  # header only
        ("x,y,z,r\n0.005,0.005,abc,0.001\n", "spheres.csv:2: column z (column 3) = 'abc': not a number"),
        (
            "x,y,z,r\n# a comment\n\n0.005,0.005,0.005,0.001\n0.007,0.005,0.005,inf\n",
            "spheres.csv:5: column r (column 4) = 'inf': not a finite number",
        ),
        ("x,y,z,r\n0.005,0.005,0.005,-0.001\n", "radii must be > 0"),
        ("", "must name columns x, y, z"),  # empty file
        (b"x,y,z,r\n\xff\xfe,0,0,0\n", "not a readable CSV"),  # not UTF-8
        # a column no one reads dropped its data without a word (every radius the case's default)
        (
            "x,y,z,radius\n0.005,0.005,0.005,0.001\n",
            "spheres.csv:1: unknown column 'radius' (the radius column is r)",
        ),
        (
            "x,y,z,r,vx,vz\n0.005,0.005,0.005,0.001,1,0\n",
            "spheres.csv:1: columns vx, vz without the rest of vx, vy, vz",
        ),
    ],
    ids=[
        "ragged-row",
        "no-xyz-header",
        "no-rows",
        "not-a-number",
        "not-finite-after-a-comment",
        "negative-radius",
        "empty-file",
        "not-utf8",
        "unknown-column",
        "part-of-a-vector",
    ],
)
def test_malformed_csv_names_the_file(tmp_path, csv, fragment):
    """`run` refuses the file, and so does `validate` (which read no placement file: a batch job
    validated before it was queued failed at its start)."""
    _file_case(tmp_path, None)
    if isinstance(csv, bytes):
        (tmp_path / "spheres.csv").write_bytes(csv)
    else:
        (tmp_path / "spheres.csv").write_text(csv)
    for command in (("run", "case.toml", "-o", "out", "-q"), ("validate", "case.toml")):
        result = sphere_inproc(*command, cwd=tmp_path)
        assert_clean_error(result, 65, "spheres.csv", fragment)


def test_placement_hdf5_that_is_not_hdf5(tmp_path):
    text = edit(FROM_FILE, "spheres.csv", "spheres.h5")
    (tmp_path / "case.toml").write_text(text)
    (tmp_path / "spheres.h5").write_text("not hdf5\n")
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(result, 65, "spheres.h5", "not a readable HDF5")


# --- the run directory -----------------------------------------------------------------------------


def test_output_under_a_regular_file_is_an_io_error(tmp_path):
    # chmod does not stop root, so make the parent a regular file instead of a read-only directory.
    (tmp_path / "case.toml").write_text(TINY)
    (tmp_path / "plain").write_text("I am a file\n")
    result = sphere("run", "case.toml", "-o", "plain/run", "-q", cwd=tmp_path)
    assert_clean_error(result, 74, "plain/run", "cannot create the run directory")
    assert (tmp_path / "plain").read_text() == "I am a file\n"


def test_output_that_is_a_regular_file_is_an_io_error(tmp_path):
    (tmp_path / "case.toml").write_text(TINY)
    (tmp_path / "plain").write_text("I am a file\n")
    result = sphere_inproc("run", "case.toml", "-o", "plain", "-q", cwd=tmp_path)
    assert_clean_error(result, 74, "plain", "not a directory")
    assert (tmp_path / "plain").read_text() == "I am a file\n"


def test_existing_run_directory_needs_overwrite(tmp_path):
    (tmp_path / "case.toml").write_text(TINY)
    assert_clean_error(sphere("run", "case.toml", "-o", "out", "-q", cwd=tmp_path), 0)
    marker = tmp_path / "out" / "mine.txt"
    marker.write_text("keep me")
    result = sphere("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(result, 2, "out", "--overwrite")
    assert marker.exists(), "a refused run must not touch the existing directory"
    result = sphere("run", "case.toml", "-o", "out", "-q", "--overwrite", cwd=tmp_path)
    assert_clean_error(result, 2, "out", "files sphere did not write (mine.txt)")
    assert marker.read_text() == "keep me", "--overwrite must not delete a file sphere did not write"
    marker.unlink()
    result = sphere("run", "case.toml", "-o", "out", "-q", "--overwrite", cwd=tmp_path)
    assert_clean_error(result, 0)
    assert (tmp_path / "out" / "trajectory.h5").is_file()


@pytest.mark.parametrize("variable", ["OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "MV2_COMM_WORLD_SIZE"])
def test_a_library_run_started_as_several_mpi_ranks_is_refused(tmp_path, monkeypatch, variable):
    """api.run under `mpiexec -n 2` (the variable each launcher sets in every rank), outside the
    `sphere run` command that joins the ranks into one scene (tests/cli/test_ranks.py): two
    copies of one scene would race for one run directory; refused before anything is written."""
    (tmp_path / "case.toml").write_text(TINY)
    monkeypatch.setenv(variable, "2")
    with pytest.raises(UsageError, match=f"{variable}=2.*mpiexec -n N sphere run.*sphere sweep"):
        api.run(tmp_path / "case.toml", tmp_path / "out")
    assert not (tmp_path / "out").exists()
    with pytest.raises(UsageError, match=f"{variable}=2"):
        api.resume(tmp_path / "out")
    monkeypatch.setenv(variable, "1")  # one rank: an ordinary run
    refuse_many_ranks(joined=False)


def test_mpiexec_refuses_library_runs_in_every_rank(tmp_path):
    """The real launcher (the mpich wheel of the test extra): a script calling api.run started
    on 2 ranks stops in both with the message and writes nothing."""
    mpiexec = Path(sys.executable).with_name("mpiexec")
    if not mpiexec.is_file():
        pytest.skip("no mpiexec beside this Python (the test extra installs the mpich wheel on Linux)")
    (tmp_path / "case.toml").write_text(TINY)
    script = "from sphere_cli import api; api.run('case.toml', 'out')"
    command = [str(mpiexec), "-n", "2", sys.executable, "-c", script]
    done = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert done.returncode != 0
    assert done.stderr.count("UsageError: started as 2 MPI ranks") == 2, done.stderr
    assert not (tmp_path / "out").exists()


def test_overwrite_refuses_a_directory_that_is_not_a_run(tmp_path):
    (tmp_path / "case.toml").write_text(TINY)
    (tmp_path / "thesis").mkdir()
    (tmp_path / "thesis" / "chapter1.tex").write_text("precious")
    result = sphere("run", "case.toml", "-o", "thesis", "-q", "--overwrite", cwd=tmp_path)
    assert_clean_error(result, 2, "thesis", "sphere did not create this directory", "chapter1.tex")
    assert (tmp_path / "thesis" / "chapter1.tex").read_text() == "precious"


# --- resume ----------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def finished_run(tmp_path_factory) -> Path:
    """A completed tiny run (checkpoints at steps 1700, 1750 and 1779); copy it before changing it."""
    root = tmp_path_factory.mktemp("finished")
    (root / "case.toml").write_text(TINY)
    result = sphere("run", "case.toml", "-o", "run", "-q", cwd=root)
    assert_clean_error(result, 0)
    return root / "run"


@pytest.fixture
def run_copy(finished_run, tmp_path) -> Path:
    target = tmp_path / "run"
    shutil.copytree(finished_run, target)
    return target


def _checkpoints(run: Path) -> list[Path]:
    return sorted((run / "checkpoints").glob("ckpt-*.h5"))


def _flip_bytes_in_positions(path: Path) -> None:
    """Corrupt the stored positions of a checkpoint without touching its HDF5 structure: its
    fletcher32 checksum must catch it."""
    with h5py.File(path, "r") as f:
        info = f["sphere/state/particles/pos"].id.get_chunk_info(0)
    with open(path, "r+b") as raw:
        raw.seek(info.byte_offset + info.size // 2)
        byte = raw.read(1)
        raw.seek(-1, 1)
        raw.write(bytes([byte[0] ^ 0xFF]))


def test_resume_until_a_time_the_run_has_passed_says_so(tmp_path):
    """`resume --until` earlier than where the run stopped steps nothing, as before, but says
    why on the terminal and in run.log (it was a silent "done" at the later time)."""
    (tmp_path / "case.toml").write_text(TINY)
    assert sphere("run", "case.toml", "-o", "run", "-q", "--until", "0.001", cwd=tmp_path).code == 0
    result = sphere("resume", "run", "-q", "--until", "0.0005", cwd=tmp_path)
    assert result.code == 0, result.stderr
    said = "warning: the end asked for, t = 0.0005 s"
    assert f"sphere: {said}" in result.stderr and "is before where the run is" in result.stderr
    assert said.removeprefix("warning: ") in (tmp_path / "run" / "run.log").read_text()


def test_resume_of_a_directory_that_is_not_a_run(tmp_path):
    (tmp_path / "empty").mkdir()
    assert_clean_error(sphere("resume", "empty", cwd=tmp_path), 66, "empty", "not a run directory")
    assert_clean_error(sphere("resume", "nowhere", cwd=tmp_path), 66, "nowhere")
    # the user's folder of cases: `sphere resume .` there would have started a run in it
    cases = tmp_path / "cases"
    cases.mkdir()
    (cases / "case.toml").write_text(TINY)
    for command in ("resume", "inspect"):
        assert_clean_error(
            sphere(command, "cases", cwd=tmp_path), 66, "cases: not a run directory: it holds a case.toml",
            "give the directory that `sphere run -o` made",
        )  # fmt: skip
    assert [entry.name for entry in cases.iterdir()] == ["case.toml"]


def test_resume_with_every_checkpoint_truncated(run_copy):
    checkpoints = _checkpoints(run_copy)
    assert [p.name for p in checkpoints] == [
        "ckpt-000000001700.h5",
        "ckpt-000000001750.h5",
        f"ckpt-{TINY_END_STEP:012d}.h5",
    ]
    for path in checkpoints:
        with open(path, "r+b") as f:
            f.truncate(path.stat().st_size // 2)
    result = sphere("resume", run_copy, "-q")
    # Nothing usable to resume from: missing input (66), naming the checkpoint directory.
    assert_clean_error(result, 66, str(run_copy / "checkpoints"), "no checkpoint that verifies")
    log = (run_copy / "run.log").read_text()
    for path in checkpoints:
        assert f"skipping {path.name}" in log


@pytest.mark.parametrize("damage", ["truncated", "checksum"])
def test_resume_falls_back_past_a_corrupt_newest_checkpoint(run_copy, damage):
    newest = _checkpoints(run_copy)[-1]
    assert newest.name == f"ckpt-{TINY_END_STEP:012d}.h5"
    if damage == "truncated":
        with open(newest, "r+b") as f:
            f.truncate(1000)
    else:
        _flip_bytes_in_positions(newest)
    assert_clean_error(sphere("inspect", newest), 74, newest.name)
    result = sphere("resume", run_copy, "-q")
    assert_clean_error(result, 0)
    log = (run_copy / "run.log").read_text()
    assert f"skipping {newest.name}" in log
    assert "resuming from ckpt-000000001750.h5 (step 1750)" in log
    assert f"done at step {TINY_END_STEP}" in log.splitlines()[-1]
    assert_clean_error(sphere("inspect", newest), 0)  # rewritten by the resumed run


def test_resume_refused_after_a_physics_edit(run_copy):
    case = run_copy / "case.toml"
    case.write_text(edit(case.read_text(), "normal_stiffness = 1.0e4", "normal_stiffness = 2.0e4"))
    result = sphere("resume", run_copy, "-q")
    assert_clean_error(result, 78, str(case), "contact.normal_stiffness", f"ckpt-{TINY_END_STEP:012d}.h5")
    assert _checkpoints(run_copy)[-1].name == f"ckpt-{TINY_END_STEP:012d}.h5"


def test_resume_refused_names_every_changed_key(run_copy):
    case = run_copy / "case.toml"
    text = edit(case.read_text(), "density = 2500.0", "density = 2600.0")
    text = edit(text, "lower = [0.0, 0.0, 0.0]", "lower = [0.0, 0.0, 0.0]\ngravity = [0.0, 0.0, -1.0]")
    case.write_text(text)
    result = sphere_inproc("resume", run_copy, "-q")
    assert_clean_error(result, 78, "particles.density", "domain.gravity")


def test_resume_accepts_an_output_edit(run_copy):
    case = run_copy / "case.toml"
    case.write_text(
        edit(case.read_text(), "[output.frames]\nevery_steps = 50", "[output.frames]\nevery_steps = 20")
    )
    result = sphere_inproc("resume", run_copy, "-q", "--until", 0.0025)
    assert_clean_error(result, 0)


def test_resume_with_a_broken_run_case_file(run_copy):
    case = run_copy / "case.toml"
    text = edit(case.read_text(), "count = 20", "count = -20")
    case.write_text(text)
    result = sphere_inproc("resume", run_copy, "-q")
    assert_clean_error(result, 65, f"{case}:{line_of(text, 'count =')}:", "particles.count")


# --- inspect ---------------------------------------------------------------------------------------


def test_inspect_missing_path(tmp_path):
    assert_clean_error(sphere("inspect", tmp_path / "nowhere.h5"), 66, "nowhere.h5")


def test_inspect_a_file_that_is_not_hdf5(tmp_path):
    """An .h5 file that is not HDF5 reads as a damaged output (74, as a checkpoint failing its
    verification); any other file holding nothing usable is missing input (66), the message
    saying what the command reads."""
    path = tmp_path / "notes.h5"
    path.write_text("hello\n")
    assert_clean_error(sphere("inspect", path), 74, "notes.h5", "not a readable HDF5 file", "damaged")
    path = path.rename(tmp_path / "notes.txt")
    assert_clean_error(
        sphere_inproc("inspect", path), 66, "notes.txt", "not a readable HDF5 file", "reads a run directory"
    )


@pytest.mark.parametrize("command", ["inspect", "plot"])
@pytest.mark.parametrize(
    ("name", "hint"),
    [
        ("case.toml", "it looks like a case file, which `sphere validate` checks"),
        ("trajectory.xmf", "it is the XDMF description ParaView opens: give trajectory.h5 beside it"),
    ],
)
def test_inspect_and_plot_of_a_file_a_run_does_not_write_say_what_it_is(tmp_path, command, name, hint):
    """The case file or ParaView's sidecar given where a run's output is read (exit 66): the
    message names what the file looks like and what to give instead."""
    path = tmp_path / name
    path.write_text('title = "x"\n' if name.endswith(".toml") else "<Xdmf/>\n")
    assert_clean_error(sphere_inproc(command, path), 66, name, hint)


def test_inspect_a_directory_that_is_not_a_run(tmp_path):
    assert_clean_error(sphere_inproc("inspect", tmp_path), 66, str(tmp_path), "not a run directory")


def test_inspect_a_run_with_damaged_files(run_copy):
    """A damaged run directory is still summarised: each damaged part says what is wrong."""
    (run_copy / "status.json").write_text("{ half a status")
    for path in _checkpoints(run_copy):
        with open(path, "r+b") as f:
            f.truncate(100)
    result = sphere_inproc("inspect", run_copy, "--json")
    assert_clean_error(result, 0)
    import json

    summary = json.loads(result.stdout)
    assert "error" in summary["status"]
    assert [c["valid"] for c in summary["checkpoints"]] == [False, False, False]


def test_auto_dt_without_any_possible_contact(tmp_path):
    """One particle and no walls: no contact limits dt, so "auto" is refused with a clear message."""
    text = edit(TINY, "count = 20", "count = 1")
    text = edit(text, '[[walls]]\nface = "z-"\n', "")
    (tmp_path / "case.toml").write_text(text)
    result = sphere("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(result, 65, "simulation.dt")
    assert "no contact can occur" in result.stderr


def test_small_spheres_from_a_file_fit_a_small_box(tmp_path):
    """The box is measured against the file's radii (10 um), not the radius distribution's
    default (1 mm), which the file overrides."""
    text = edit(FROM_FILE, "upper = [0.01, 0.01, 0.01]", "upper = [0.001, 0.001, 0.001]")
    _file_case(tmp_path, "x,y,z,r\n0.0003,0.0005,0.0005,1e-5\n0.0007,0.0005,0.0005,1e-5\n", text)
    assert_clean_error(sphere_inproc("validate", "case.toml", cwd=tmp_path), 0)
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", "--until", "1e-7", cwd=tmp_path)
    assert_clean_error(result, 0)


def test_a_sphere_from_a_file_larger_than_the_box(tmp_path):
    text = edit(FROM_FILE, "upper = [0.01, 0.01, 0.01]", "upper = [0.001, 0.001, 0.001]")
    _file_case(tmp_path, "x,y,z,r\n0.0005,0.0005,0.0005,0.0006\n", text)
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(result, 65, "domain.upper", "smaller than the largest particle diameter 0.0012 m")
    assert not (tmp_path / "out").exists()


def test_initial_angular_velocity_from_the_case_and_from_a_file(tmp_path):
    """particles.angular_velocity for every particle; wx, wy, wz columns of a placement file win
    over it; a particle of a fixed group does not spin."""
    from sphere_cli.api import run_in_memory

    spin = edit(TINY, "density = 2500.0", "density = 2500.0\nangular_velocity = [0.0, 0.0, 30.0]")
    state = run_in_memory(spin, 0).state
    assert np.array_equal(state.particles.angvel, np.tile([0.0, 0.0, 30.0], (20, 1)))
    assert np.array_equal(state.particles.angvel_pred, state.particles.angvel)
    text = FROM_FILE.replace("density = 2500.0", "density = 2500.0\nangular_velocity = [1.0, 1.0, 1.0]")
    text += (
        "[[particles.groups]]\nregion_lower = [0.0, 0.0, 0.0]\nregion_upper = [0.005, 0.01, 0.01]\n"
        'motion = "fixed"\n'
    )
    _file_case(
        tmp_path, "x,y,z,r,wx,wy,wz\n0.003,0.005,0.005,0.001,0,0,5\n0.007,0.005,0.005,0.001,0,-2,0\n", text
    )
    state = run_in_memory(text, 0, tmp_path).state
    assert np.array_equal(state.particles.angvel, [[0.0, 0.0, 0.0], [0.0, -2.0, 0.0]])  # the first is fixed
    _file_case(tmp_path, "x,y,z,r,wx,wy,wz\n0.007,0.005,0.005,0.001,0,1,nan\n", text)
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(result, 65, "spheres.csv:2: column wz (column 7) = 'nan': not a finite number")


@pytest.mark.parametrize("value", ["0", "-2"])
def test_a_thread_count_of_zero_in_the_environment_is_refused_by_name(tmp_path, value):
    """NUMBA_NUM_THREADS=0 (a batch script's arithmetic on an empty allocation) made `import
    numba` fail: every command ended in a traceback. It is refused by name, exit 2."""
    (tmp_path / "case.toml").write_text(TINY)
    result = subprocess.run(
        [sys.executable, "-m", "sphere_cli.cli", "validate", "case.toml"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "NUMBA_NUM_THREADS": value},
    )
    assert result.returncode == 2, result.stderr
    assert result.stderr == (
        f"sphere: error: NUMBA_NUM_THREADS = '{value}': expected a whole number of threads of at least 1; "
        "unset it to use every core this process may run on\n"
    )
