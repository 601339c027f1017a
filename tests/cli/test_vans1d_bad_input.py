"""Bad input to `[fluid] model = "vans1d"`: a short message naming the key and its line, exit 65,
no traceback (design guide section 6)."""

from __future__ import annotations

import warnings

import pytest
from cli_test_support import assert_clean_error, edit, line_of, sphere, sphere_inproc

CASE = """\
[simulation]
duration = 0.0002
dt = "auto"

[domain]
upper = [0.006, 0.006, 0.01]
periodic = [true, true, false]
gravity = [0.5, 0.0, -9.8]

[particles]
count = 8
density = 2500.0
radius = { distribution = "fixed", value = 0.001 }
placement = { method = "lattice" }

[contact]
normal_stiffness = 1.0e4

[[walls]]
face = "z-"

[fluid]
model = "vans1d"
viscosity = 1.0e-6
surface = 0.008
cells = 20
flow = { kind = "solved", mixing_length = "li-sawamoto" }
"""

# (id, text to replace, replacement, key named, text on the line named, other fragments)
ERRORS = [
    (
        "negative-viscosity",
        "viscosity = 1.0e-6",
        "viscosity = -1.0e-6",
        "fluid.viscosity",
        "viscosity",
        ["greater than 0"],
    ),
    (
        "not-periodic-in-x",
        "periodic = [true, true, false]",
        "periodic = [false, true, false]",
        "domain.periodic",
        "periodic",
        ["laterally periodic"],
    ),
    (
        "surface-above-the-box",
        "surface = 0.008",
        "surface = 0.02",
        "fluid.surface",
        "surface",
        ["inside the box"],
    ),
    (
        "gravity-along-y",
        "gravity = [0.5, 0.0, -9.8]",
        "gravity = [0.5, 0.1, -9.8]",
        "domain.gravity",
        "gravity",
        ["y"],
    ),
    (
        "lid-with-turbulence",
        'flow = { kind = "solved", mixing_length = "li-sawamoto" }',
        'flow = { kind = "solved", mixing_length = "li-sawamoto", top = "no-slip" }',
        "fluid.flow",
        "flow =",
        ["laminar only"],
    ),
    (
        "profile-not-increasing",
        'flow = { kind = "solved", mixing_length = "li-sawamoto" }',
        'flow = { kind = "profile", z = [0.0, 0.005, 0.004], u = [0.0, 0.1, 0.2] }',
        "fluid.flow",
        "flow =",
        ["increase"],
    ),
    (
        "unknown-material",
        "cells = 20",
        'cells = 20\nmaterials = ["sand"]',
        "fluid.materials",
        "materials",
        ["sand"],
    ),
    ("few-cells", "cells = 20", "cells = 1", "fluid.cells", "cells", ["greater than or equal to 2"]),
    (
        # (1 - c)^-n overflowed a float in the drag's relaxation limit: a traceback, not an error
        "drag-exponent-beyond-any-measured",
        "cells = 20",
        "cells = 20\ndrag_exponent = 1e300",
        "fluid.drag_exponent",
        "drag_exponent",
        ["less than or equal to 10"],
    ),
    ("ids-reversed", "cells = 20", "cells = 20\nids = [5, 2]", "fluid.ids", "ids", ["first <= last"]),
    (
        "solid-fraction-of-one",
        "cells = 20",
        "cells = 20\nsolid_fraction = { z = [0.0, 0.01], value = [0.6, 1.0] }",
        "fluid.solid_fraction",
        "solid_fraction",
        ["1.0", "0 <= value < 1"],
    ),
    (
        "solid-fraction-points",
        "cells = 20",
        "cells = 20\nsolid_fraction = { z = [0.0, 0.01, 0.02], value = [0.6, 0.3] }",
        "fluid.solid_fraction",
        "solid_fraction",
        ["z has 3 points but value has 2"],
    ),
    (
        "fluctuations-without-a-solved-flow",
        'flow = { kind = "solved", mixing_length = "li-sawamoto" }',
        'flow = { kind = "log-law", friction_velocity = 0.05, bed_level = 0.002, roughness_length = 1e-4 }'
        "\nfluctuations = { bed_elevation = 0.002 }",
        "fluid.fluctuations",
        "fluctuations",
        ['flow.kind = "solved"', "Reynolds stress"],
    ),
    (
        "fluctuations-without-a-bed-elevation",
        "cells = 20",
        "cells = 20\nfluctuations = { seed = 3 }",
        "fluid.fluctuations.bed_elevation",
        "fluctuations",
        ["required key is missing"],
    ),
    (
        "lid-velocity-without-a-lid",
        'mixing_length = "li-sawamoto" }',
        'mixing_length = "li-sawamoto", top_velocity = 0.5 }',
        "fluid.flow",
        "flow =",
        ['top = "no-slip"'],
    ),
]


@pytest.mark.parametrize(
    ("old", "new", "key", "marker", "fragments"), [e[1:] for e in ERRORS], ids=[e[0] for e in ERRORS]
)
def test_vans1d_bad_input_names_key_and_line(tmp_path, old, new, key, marker, fragments):
    text = edit(CASE, old, new)
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(result, 65, key, f"case.toml:{line_of(text, marker)}:", *fragments)
    assert not (tmp_path / "out").exists()


def test_the_valid_case_runs(tmp_path):
    (tmp_path / "case.toml").write_text(CASE)
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert result.code == 0, result.stderr


def test_dt_above_the_drag_relaxation_limit_is_refused(tmp_path):
    """A very viscous fluid (nu = 1 m^2/s): the viscous drag relaxes a 2 mm bead in about 3e-8 s,
    so dt = 1e-5 s is refused naming that limit."""
    text = edit(edit(CASE, "viscosity = 1.0e-6", "viscosity = 1.0"), 'dt = "auto"', "dt = 1.0e-5")
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(result, 65, "simulation.dt", "explicit drag", "relaxation time")


def test_runaway_drag_is_caught_and_named(tmp_path):
    """A prescribed 2000 m/s stream: the quadratic drag relaxes the beads in about 8e-6 s, below
    dt = 1.5e-5 s (under the contact limit); the stability guard stops the run (exit 70) naming
    the particle and the cause."""
    text = edit(
        edit(CASE, 'dt = "auto"', 'dt = 1.5e-5\nstability = "contact"\nblowup_check_every = 1'),
        'flow = { kind = "solved", mixing_length = "li-sawamoto" }',
        'flow = { kind = "profile", z = [0.0, 0.008], u = [2000.0, 2000.0] }',
    )
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(result, 70, "drag relaxation time", "particle")


def test_both_sublayer_treatments_are_refused(tmp_path):
    """van_driest and viscous_sublayer treat the same sublayer: giving both is refused, naming the
    key and its line."""
    text = edit(
        CASE,
        'mixing_length = "li-sawamoto" }',
        'mixing_length = "li-sawamoto", van_driest = 26.0, viscous_sublayer = 11.3 }',
    )
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("validate", tmp_path / "case.toml")
    assert_clean_error(result, 65, "fluid.flow", "van_driest and viscous_sublayer")


CLEAR_WATER = """\
[simulation]
duration = 0.002
[domain]
upper = [0.01, 0.01, 0.1]
periodic = [true, true, false]
gravity = [0.490296, 0.0, -9.797740]
[fluid]
model = "vans1d"
surface = 0.1
cells = 100
stretching = 1.0e4
flow = {{ kind = "solved", mixing_length = "prandtl"{extra} }}
"""


@pytest.mark.parametrize(
    ("extra", "warned"), [("", True), (", viscous_sublayer = 11.3", False), (", van_driest = 26.0", False)]
)
def test_a_smooth_floor_without_a_sublayer_treatment_is_warned(tmp_path, extra, warned):
    """Prandtl's mixing length over a clear floor reaches the floor (log-law intercept -1.2): the
    run warns, naming both treatments, in run.log (as every warning) and on stderr; with either
    treatment there is no warning."""
    (tmp_path / "case.toml").write_text(CLEAR_WATER.format(extra=extra))
    with warnings.catch_warnings():
        warnings.simplefilter("always")
        result = sphere_inproc("run", tmp_path / "case.toml", "--output", tmp_path / "run")
    assert result.code == 0, result.stderr
    log = (tmp_path / "run" / "run.log").read_text()
    assert ("has no viscous-sublayer treatment" in log) == warned, log
    if warned:
        assert "van_driest = 26" in log and "viscous_sublayer = 11.3" in log


def test_warnings_reach_stderr_and_run_log_in_a_real_run(tmp_path):
    """The real CLI in its own interpreter: the warning is printed on stderr as the case's
    warnings are (`sphere: warning: ...`, not Python's file:line form with a line of sphere's
    source) and written to run.log."""
    (tmp_path / "case.toml").write_text(CLEAR_WATER.format(extra=""))
    result = sphere("run", tmp_path / "case.toml", "--output", tmp_path / "run")
    assert result.code == 0, result.stderr
    assert "sphere: warning: fluid.flow.mixing_length" in result.stderr, result.stderr
    assert "has no viscous-sublayer treatment" in result.stderr
    assert ".py:" not in result.stderr and "RuntimeWarning" not in result.stderr, result.stderr
    assert "RuntimeWarning: " in (tmp_path / "run" / "run.log").read_text()


def test_a_steady_start_that_diverges_is_refused_naming_the_key(tmp_path):
    """A driving beyond any flow (gravity along the slope of 1e300 m/s^2): the implicit steady
    start's profile goes to inf and nan (a pivot of its solve then divides by zero, which was a
    traceback); refused with exit 65 naming fluid.flow.initial and what drives it."""
    text = edit(CASE, "gravity = [0.5, 0.0, -9.8]", "gravity = [1e300, 0.0, -9.8]")
    flow = 'mixing_length = "li-sawamoto"'
    text = edit(text, f"{flow} }}", f'{flow}, initial = "steady" }}')
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(result, 65, "fluid.flow.initial", "went non-finite", "domain.gravity")


def test_an_id_range_beyond_the_particles_is_refused(tmp_path):
    """fluid.ids past the last particle is refused when the scene is built, naming the key and the
    number of particles."""
    text = edit(CASE, "cells = 20", "cells = 20\nids = [4, 8]")
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("run", tmp_path / "case.toml", "--output", tmp_path / "run")
    assert_clean_error(result, 65, "fluid.ids", "8 particles (0 .. 7)")


def test_inspect_estimates_the_steady_transport(tmp_path):
    """`sphere inspect` of a bedload run gives, for q_star and shields_number (every scalar
    observable), the mean of the latter half with its batch-means error and the drift."""
    text = edit(CASE, "duration = 0.0002", "duration = 0.0008") + "[output.observables]\nevery_steps = 1\n"
    (tmp_path / "case.toml").write_text(text)
    assert sphere_inproc("run", tmp_path / "case.toml", "--output", tmp_path / "run").code == 0
    result = sphere_inproc("inspect", tmp_path / "run")
    assert result.code == 0, result.stderr
    assert "steady_state:" in result.stdout
    line = next(x for x in result.stdout.splitlines() if x.strip().startswith("q_star:") and "+-" in x)
    assert "batch means of the last half" in line and "drift" in line
