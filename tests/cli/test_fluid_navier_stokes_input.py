"""Bad input to the Navier-Stokes fluid (`[fluid] model = "navier-stokes"`): a short message naming
the TOML key and line, exit 65 before anything runs (70 for a fluid that outruns its limit during
the run, naming the cell), no traceback."""

from __future__ import annotations

import re

import pytest
from cli_test_support import NAVIER_STOKES_SCENE, assert_clean_error, edit, line_of, sphere_inproc

FLUID = (
    'title = "fluid"\n\n'
    + NAVIER_STOKES_SCENE
    + """viscosity = 0.001
old_pressure_weight = 0.0
formulation = "A"
top = { type = "pressure", pressure = 0.0 }

[fluid.solver]
method = "pcg"

[fluid.coupling]
steps = 5
"""
)

# (id, text to replace, replacement, key named, text on the line named, other fragments)
SCHEMA_ERRORS = [
    (
        "weight-above-1",
        "old_pressure_weight = 0.0",
        "old_pressure_weight = 1.5",
        "fluid.old_pressure_weight",
        "old_pressure_weight =",
        [],
    ),
    ("formulation", 'formulation = "A"', 'formulation = "C"', "fluid.formulation", "formulation =", []),
    ("solver-method", 'method = "pcg"', 'method = "sor"', "fluid.solver.method", 'method = "sor"', []),
    ("steps-zero", "steps = 5", "steps = 0", "fluid.coupling.steps", "steps =", []),
    (
        "steps-and-interval",
        "steps = 5",
        "steps = 5\ninterval = 1e-4",
        "fluid.coupling",
        "[fluid.coupling]",
        ["not both"],
    ),
    ("boundary-type", 'type = "pressure"', 'type = "open"', "fluid.top", "top =", []),
    ("negative-viscosity", "viscosity = 0.001", "viscosity = -1.0", "fluid.viscosity", "viscosity =", []),
    (
        "velocity-and-flux",
        'top = { type = "pressure", pressure = 0.0 }',
        'top = { type = "velocity", velocity = 0.01, flux = 1e-6 }',
        "fluid.top",
        "top =",
        ["either velocity", "or flux"],
    ),
    (
        "velocity-without-an-open-face",
        'top = { type = "pressure", pressure = 0.0 }',
        'top = { type = "velocity", velocity = 0.01 }',
        "fluid",
        "[fluid]",
        ['"velocity" needs the other one of type "pressure"'],
    ),
    (
        "initial-expression",
        "viscosity = 0.001",
        'viscosity = 0.001\ninitial = { velocity = ["sin(2*pi*x", "0", "0"] }',
        "fluid.initial.velocity[0]",
        "initial =",
        ['"sin(2*pi*x"', 'or ")"', "found the end"],
    ),
    (
        "initial-unknown-name",
        "viscosity = 0.001",
        'viscosity = 0.001\ninitial = { pressure = "1000*r" }',
        "fluid.initial.pressure",
        "initial =",
        ['unknown name "r"'],
    ),
    (
        "initial-file-and-expression",
        "viscosity = 0.001",
        'viscosity = 0.001\ninitial = { pressure = "0", file = "f.h5" }',
        "fluid.initial",
        "initial =",
        ["either as expressions", "or in a file"],
    ),
    (
        "body-force-neither",
        "viscosity = 0.001",
        "viscosity = 0.001\nbody_force = {}",
        "fluid.body_force",
        "body_force =",
        ["one of them"],
    ),
    (
        "typo",
        "old_pressure_weight = 0.0",
        "old_presure_weight = 0.0",
        "fluid.old_presure_weight",
        "old_presure_weight",
        ["unknown key"],
    ),
]


@pytest.mark.parametrize(
    ("old", "new", "key", "marker", "fragments"),
    [e[1:] for e in SCHEMA_ERRORS],
    ids=[e[0] for e in SCHEMA_ERRORS],
)
def test_fluid_schema_error_names_key_and_line(tmp_path, old, new, key, marker, fragments):
    text = edit(FLUID, old, new)
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("validate", tmp_path / "case.toml")
    assert_clean_error(result, 65, key, f"case.toml:{line_of(text, marker)}:", *fragments)


def _run(tmp_path, text, command: str = "run"):
    """`sphere run` (or `sphere validate`) of the case `text`."""
    (tmp_path / "case.toml").write_text(text)
    if command == "validate":
        return sphere_inproc("validate", "case.toml", cwd=tmp_path)
    return sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)


def test_fluid_needs_periodic_x_and_y(tmp_path):
    text = edit(FLUID, "periodic = [true, true, false]", "periodic = [true, false, false]")
    result = _run(tmp_path, text)
    assert_clean_error(
        result, 65, "domain.periodic", f"case.toml:{line_of(text, 'periodic =')}:", "x and y periodic"
    )
    assert not (tmp_path / "out").exists()


def test_dt_above_the_viscous_limit_names_it(tmp_path):
    """A viscous fluid (nu = 0.1 m^2/s on 2.5 mm cells: dx^2/(8 nu) = 7.8 us, 1.6 us per DEM step
    with fluid.coupling.steps = 5) limits dt below the contact limit (~23 us): a given dt above
    it is refused."""
    text = edit(edit(FLUID, "viscosity = 0.001", "viscosity = 100.0"), 'dt = "auto"', "dt = 1e-5")
    result = _run(tmp_path, text)
    assert_clean_error(result, 65, "simulation.dt", "viscous diffusion", "steps = 5")
    limit = float(re.search(r"stability limit ([0-9.eE+-]+) s", result.stderr).group(1))
    assert limit == pytest.approx(0.25**2 * 1e-4 / (8 * 0.1) / 5, rel=1e-3)  # printed to 4 digits


def test_dt_above_the_advective_limit_of_max_speed_names_it(tmp_path):
    """fluid.max_speed = 50 m/s on 2.5 mm cells: the advective limit sum |u| dt_f/dx <= 1/2 (the
    bound of the limited advection, kernels/fluid/navier_stokes.py) gives dt_f <= 0.5/(50 * 3/2.5e-3)
    = 8.33 us, 1.67 us per DEM step with 5 DEM steps a fluid step, below the contact limit (6.9 us): a given
    dt = 5e-6 s is refused naming it (with the factor 1 of first-order upwind it would be 3.3 us)."""
    text = edit(FLUID, "viscosity = 0.001", "viscosity = 0.001\nmax_speed = 50.0")
    text = edit(text, 'dt = "auto"', "dt = 5e-6")
    result = _run(tmp_path, text)
    assert_clean_error(result, 65, "simulation.dt", "advective limit", "fluid.max_speed = 50", "steps = 5")
    limit = float(re.search(r"stability limit ([0-9.eE+-]+) s", result.stderr).group(1))
    assert limit == pytest.approx(0.5 / (50.0 * 3 / 2.5e-3) / 5, rel=1e-3)  # printed to 4 digits


def test_grid_finer_than_the_particles_is_refused(tmp_path):
    text = edit(FLUID, "cells = [4, 4, 8]", "cells = [20, 4, 8]")
    result = _run(tmp_path, text)
    assert_clean_error(result, 65, "fluid.grid.cells", "diameter")


def test_fluid_outrunning_the_advective_limit_stops_naming_the_cell(tmp_path):
    """A pressure drop of 1e8 Pa over the 2 cm column accelerates the fluid at ~5e6 m/s^2: with a
    fluid step of 50 DEM steps the Courant number passes 1/2 (at ~35 m/s) within a few fluid steps,
    and the particles dragged along cross more than a cell a fluid step: the run stops (exit 70)
    before any NaN, naming the fluid cell or the particle that outran the coupling, whichever the
    check meets first (here the particle, at 1.4 cells a fluid step)."""
    text = edit(
        FLUID, 'top = { type = "pressure", pressure = 0.0 }', 'bottom = { type = "pressure", pressure = 1e8 }'
    )
    text = edit(text, "steps = 5", "steps = 50")
    text = edit(text, 'dt = "auto"', 'dt = "auto"\nblowup_check_every = 5')
    result = _run(tmp_path, text)
    assert_clean_error(result, 70, "numerical failure")
    assert ("fluid cell (" in result.stderr and "Courant number" in result.stderr) or (
        "cells (0.0025 m) a fluid step" in result.stderr and "particle " in result.stderr
    ), result.stderr


# an interval above the viscous limit dx^2/(8 nu), and one just below it (7.8125e-4 s at nu =
# 1e-3 m^2/s) that is 1411.6 steps of dt, which the one rule for spans of time makes 1412: a fluid
# step of 7.8146e-4 s
INTERVALS = [
    ("above", "viscosity = 100.0", "interval = 1e-4", None, ["viscous diffusion"]),
    (
        "rounded-above", "viscosity = 1.0", "interval = 7.8124e-4", 7.8124e-4 / 1411.6,
        ["is 1412 DEM steps", "above the fluid's stability limit 0.0007813 s"],
    ),
]  # fmt: skip


@pytest.mark.parametrize(
    "viscosity, interval, dt, fragments", [i[1:] for i in INTERVALS], ids=[i[0] for i in INTERVALS]
)
def test_a_coupling_interval_above_the_viscous_limit_is_refused(tmp_path, viscosity, interval, dt, fragments):
    text = edit(edit(FLUID, "viscosity = 0.001", viscosity), "steps = 5", interval)
    if dt is not None:
        text = edit(text, 'dt = "auto"', f"dt = {dt!r}")
    result = _run(tmp_path, text)
    where = f"case.toml:{line_of(text, 'interval =')}:"
    assert_clean_error(result, 65, "fluid.coupling.interval", where, *fragments)


def test_a_body_force_that_is_not_finite_is_refused_naming_the_point(tmp_path):
    """An expression that divides by zero somewhere on the grid: exit 65 naming the key, the
    component and where."""
    text = edit(
        FLUID, "viscosity = 0.001", 'viscosity = 0.001\nbody_force = { acceleration = ["0", "1/(x-x)", "0"] }'
    )
    result = _run(tmp_path, text)
    assert_clean_error(result, 65, "fluid.body_force.acceleration[1]", "not finite", "x=")


@pytest.mark.parametrize("command", ["validate", "run"])
def test_an_initial_field_file_that_is_missing_or_misshapen_is_refused(tmp_path, command):
    """fluid.initial.file: a missing file exits 66 naming the key; a dataset of another shape
    than the grid's exits 65 naming the dataset and both shapes. `validate` reads it as `run`
    does (it passed both before)."""
    import h5py

    text = edit(FLUID, "viscosity = 0.001", 'viscosity = 0.001\ninitial = { file = "fields.h5" }')
    result = _run(tmp_path, text, command)
    assert_clean_error(result, 66, "fluid.initial.file", "file not found")
    with h5py.File(tmp_path / "fields.h5", "w") as f:
        f["velocity_z"] = [[[0.0] * 8] * 4] * 4  # the z faces are (4, 4, 9)
    result = _run(tmp_path, text, command)
    assert_clean_error(result, 65, "fluid.initial.file", "'velocity_z'", "(4, 4, 8)", "(4, 4, 9)")


@pytest.mark.parametrize("command", ["validate", "run"])
def test_an_initial_velocity_that_is_not_finite_is_refused_naming_the_point(tmp_path, command):
    """An initial velocity expression dividing by zero on the grid: exit 65 from both commands."""
    initial = 'initial = { velocity = ["0", "0", "1/(z-z)"] }'
    text = edit(FLUID, "viscosity = 0.001", f"viscosity = 0.001\n{initial}")
    result = _run(tmp_path, text, command)
    assert_clean_error(result, 65, "fluid.initial.velocity[2]", "not finite", "z=")


@pytest.mark.parametrize(
    ("content", "code", "fragments"),
    [
        (None, 66, ["file not found"]),
        ("t,p\n0.0,1.0\n0.1\n", 65, ["top.csv:3", "expected two numbers"]),
        ("0.0,1.0\n0.0,2.0\n", 65, ["times must increase"]),
    ],
    ids=["missing", "one-column", "not-increasing"],
)
def test_a_bad_pressure_series_is_refused(tmp_path, content, code, fragments):
    """fluid.top.series: a missing file exits 66, a malformed one 65, naming the key."""
    if content is not None:
        (tmp_path / "top.csv").write_text(content)
    text = edit(
        FLUID,
        'top = { type = "pressure", pressure = 0.0 }',
        'top = { type = "pressure", series = "top.csv" }',
    )
    result = _run(tmp_path, text)
    assert_clean_error(result, code, "fluid.top.series", *fragments)


def test_a_pressure_series_excludes_a_constant_pressure(tmp_path):
    text = edit(
        FLUID,
        'top = { type = "pressure", pressure = 0.0 }',
        'top = { type = "pressure", pressure = 1.0, series = "t.csv" }',
    )
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("validate", tmp_path / "case.toml")
    assert_clean_error(result, 65, "fluid.top", "replaces pressure")
