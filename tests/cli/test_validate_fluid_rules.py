"""What a fluid model requires of the rest of the case (periodic axes, gravity, walls, boundaries,
regions, materials, particle ids) is refused by `sphere validate`, not only by `sphere run` once
the scene is built: a user validates a case before a batch job, and a job that fails at its start
after hours in the queue is what validate is for. Each rule names its key and line, exit 65
(config/fluid_navier_stokes.py, fluid_darcy.py, fluid_vans1d.py: `case_problems`)."""

from __future__ import annotations

import pytest
from cli_test_support import TINY, assert_clean_error, edit, line_of, sphere_inproc

PERIODIC_XY = edit(TINY, "[particles]", "periodic = [true, true, false]\n\n[particles]")

NAVIER_STOKES = edit(
    PERIODIC_XY, "[output.frames]", '[fluid]\nmodel = "navier-stokes"\ndensity = 1000.0\n\n[output.frames]'
)
DARCY = edit(TINY, "[output.frames]", '[fluid]\nmodel = "darcy"\n\n[output.frames]')
VANS1D = edit(
    PERIODIC_XY,
    "[output.frames]",
    '[fluid]\nmodel = "vans1d"\nsurface = 0.015\ncells = 10\n\n[output.frames]',
)
TOP_WALL = '[[walls]]\nface = "z+"\n'
# a fluid alone through a bed of imposed porosity (cell centres at z = 2.5, 7.5, 12.5, 17.5 mm)
FIXED_BED = """\
[simulation]
duration = 0.001
dt = 1e-4

[domain]
upper = [0.01, 0.01, 0.02]
periodic = [true, true, false]

[fluid]
model = "navier-stokes"
grid = { cells = [2, 2, 4] }
bed = { porosity = 0.4, diameter = 0.001, lower = 0.006, upper = 0.009 }
"""

RULES = [
    # (id, case, text to replace, replacement, key named, text on the line named, other fragments)
    (
        "navier-stokes-walled-x",
        NAVIER_STOKES,
        "periodic = [true, true, false]",
        "periodic = [false, true, false]",
        "domain.periodic",
        "periodic =",
        ["needs x and y periodic"],
    ),
    (
        "navier-stokes-one-cell-along-z",
        NAVIER_STOKES,
        "density = 1000.0\n",
        "density = 1000.0\ngrid = { cells = [2, 2, 1] }\n",
        "fluid.grid",
        "grid =",
        ["at least 2 cells along z"],
    ),
    (
        "navier-stokes-follows-a-missing-top-wall",
        NAVIER_STOKES,
        "density = 1000.0\n",
        "density = 1000.0\ngrid = { follow_top_wall = true }\n",
        "fluid.grid.follow_top_wall",
        "grid =",
        ['face = "z+"', "walls now: z-"],
    ),
    (
        "navier-stokes-follows-the-top-wall-closed",
        NAVIER_STOKES.replace('[[walls]]\nface = "z-"\n', '[[walls]]\nface = "z-"\n' + TOP_WALL),
        "density = 1000.0\n",
        'density = 1000.0\ngrid = { follow_top_wall = true }\ntop = { type = "no-flow" }\n',
        "fluid.top.type",
        "top =",
        ['use type = "pressure"'],
    ),
    (
        "navier-stokes-bed-between-the-cells",
        FIXED_BED,
        "lower = 0.006",
        "lower = 0.008",
        "fluid.bed",
        "bed =",
        ["no cell centre lies between lower and upper", "z = 0.0025 .. 0.0175 m"],
    ),
    (
        "darcy-periodic-z",
        edit(DARCY, '[[walls]]\nface = "z-"\n', ""),
        "[particles]",
        "periodic = [false, false, true]\n\n[particles]",
        "domain.periodic",
        "periodic =",
        ["bounded z axis"],
    ),
    (
        "darcy-explicit-with-fixed-pressure",
        DARCY,
        'model = "darcy"',
        'model = "darcy"\ntime_scheme = "explicit"\n[[fluid.fixed_pressure]]\nlower = [0.0, 0.0, 0.0]\n'
        "upper = [0.01, 0.01, 0.005]\npressure = 10.0",
        "fluid.time_scheme",
        "time_scheme =",
        ["fluid.fixed_pressure", 'time_scheme = "implicit"'],
    ),
    (
        "darcy-explicit-following-the-top-wall",
        DARCY.replace('[[walls]]\nface = "z-"\n', '[[walls]]\nface = "z-"\n' + TOP_WALL),
        'model = "darcy"',
        'model = "darcy"\ntime_scheme = "explicit"\ngrid = { follow_top_wall = true }',
        "fluid.time_scheme",
        "time_scheme =",
        ["fluid.grid.follow_top_wall"],
    ),
    (
        "darcy-follows-a-missing-top-wall",
        DARCY,
        'model = "darcy"',
        'model = "darcy"\ngrid = { follow_top_wall = true }',
        "fluid.grid.follow_top_wall",
        "grid =",
        ['face = "z+"'],
    ),
    (
        "darcy-fixed-pressure-on-a-moving-grid",
        DARCY.replace('[[walls]]\nface = "z-"\n', '[[walls]]\nface = "z-"\n' + TOP_WALL),
        'model = "darcy"',
        'model = "darcy"\ngrid = { follow_top_wall = true }\n[[fluid.fixed_pressure]]\n'
        "lower = [0.0, 0.0, 0.0]\nupper = [0.01, 0.01, 0.005]\npressure = 10.0",
        "fluid.fixed_pressure",
        "[[fluid.fixed_pressure]]",
        ["follow_top_wall"],
    ),
    (
        "darcy-fixed-pressure-region-without-a-cell",
        DARCY,
        "[output.frames]",
        "[[fluid.fixed_pressure]]\nlower = [0.0, 0.0, 0.0]\nupper = [0.001, 0.001, 0.001]\npressure = 1.0\n\n"
        "[output.frames]",
        "fluid.fixed_pressure[0]",
        "[[fluid.fixed_pressure]]",
        ["holds no cell centre", "1 x 1 x 3 cells", "z = 0.00333333 .. 0.0166667 m"],
    ),
    (
        "vans1d-walled-y",
        VANS1D,
        "periodic = [true, true, false]",
        "periodic = [true, false, false]",
        "domain.periodic",
        "periodic =",
        ["laterally periodic"],
    ),
    (
        "vans1d-gravity-along-y",
        VANS1D,
        "periodic = [true, true, false]",
        "periodic = [true, true, false]\ngravity = [0.0, 0.5, -9.8]",
        "domain.gravity",
        "gravity =",
        ["no y component"],
    ),
    (
        "vans1d-surface-above-the-box",
        VANS1D,
        "surface = 0.015",
        "surface = 0.03",
        "fluid.surface",
        "surface =",
        ["inside the box", "top z = 0.02 m"],
    ),
    (
        "vans1d-unknown-material",
        VANS1D,
        "cells = 10",
        'cells = 10\nmaterials = ["sand"]',
        "fluid.materials",
        "materials =",
        ["'sand'", "no particle is made of it"],
    ),
    (
        "vans1d-fluctuations-of-a-prescribed-flow",
        VANS1D,
        "cells = 10",
        'cells = 10\nflow = { kind = "log-law", friction_velocity = 0.05, bed_level = 0.002, '
        "roughness_length = 1e-4 }\n"
        "fluctuations = { bed_elevation = 0.002 }",
        "fluid.fluctuations",
        "fluctuations =",
        ['flow.kind = "solved"'],
    ),
    (
        "vans1d-ids-beyond-the-particles",
        VANS1D,
        "cells = 10",
        "cells = 10\nids = [0, 20]",
        "fluid.ids",
        "ids =",
        ["the scene has 20 particles (0 .. 19)"],
    ),
]


@pytest.mark.parametrize(
    ("case", "old", "new", "key", "marker", "fragments"),
    [r[1:] for r in RULES],
    ids=[r[0] for r in RULES],
)
def test_validate_refuses_what_the_fluid_requires_of_the_case(
    tmp_path, case, old, new, key, marker, fragments
):
    text = edit(case, old, new)
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert_clean_error(result, 65, key, f"case.toml:{line_of(text, marker)}:", *fragments)


@pytest.mark.parametrize(
    "case", [NAVIER_STOKES, FIXED_BED, DARCY, VANS1D], ids=["navier-stokes", "fixed-bed", "darcy", "vans1d"]
)
def test_the_bases_of_these_cases_are_valid(tmp_path, case):
    """Each rule's case is valid but for the rule's edit: the refusals above are the rules'."""
    (tmp_path / "case.toml").write_text(case)
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert result.code == 0, result.stderr


# Particles from a file: what their radii and count decide is known once the file is read, which
# `sphere validate` does as the build does (scene/builder.py check_build).
FROM_FILE = """\
[simulation]
duration = 0.0005

[domain]
upper = [0.01, 0.01, 0.01]
periodic = [true, true, false]

[particles]
density = 2500.0
placement = { method = "file", path = "spheres.csv" }

[contact]
normal_stiffness = 1.0e4

[[walls]]
face = "z-"

[fluid]
"""
SPHERES = "x,y,z,r\n0.003,0.005,0.002,0.001\n0.007,0.005,0.002,0.001\n"

FILE_RULES = [
    # (id, [fluid] table, key named, fragments): 2 spheres of 1 mm radius in a 1 cm cube
    (
        "navier-stokes-one-cell-along-z",  # the automatic cell, 3 diameters: 1 x 1 x 1 cells
        'model = "navier-stokes"\n',
        "fluid.grid",
        ["at least 2 cells along z"],
    ),
    (
        "darcy-cells-narrower-than-the-spheres",
        'model = "darcy"\ngrid = { cells = [8, 8, 8] }\n',
        "fluid.grid.cells",
        ["smaller than the largest particle diameter 0.002 m"],
    ),
    (
        "darcy-fixed-pressure-region-without-a-cell",  # one cell, centred at 5 mm
        'model = "darcy"\n[[fluid.fixed_pressure]]\nlower = [0.0, 0.0, 0.0]\nupper = [0.01, 0.01, 0.002]\n'
        "pressure = 1.0\n",
        "fluid.fixed_pressure[0]",
        ["holds no cell centre", "1 x 1 x 1 cells"],
    ),
    (
        "vans1d-ids-beyond-the-particles",
        'model = "vans1d"\nsurface = 0.008\ncells = 10\nids = [0, 2]\n',
        "fluid.ids",
        ["the scene has 2 particles (0 .. 1)"],
    ),
]


@pytest.mark.parametrize("command", ["validate", "run"])
@pytest.mark.parametrize(
    ("table", "key", "fragments"), [r[1:] for r in FILE_RULES], ids=[r[0] for r in FILE_RULES]
)
def test_a_placement_file_is_checked_against_the_fluid(tmp_path, command, table, key, fragments):
    """Both `sphere validate` and `sphere run` refuse what the file's radii or count break,
    naming the key, with nothing written."""
    (tmp_path / "case.toml").write_text(FROM_FILE + table)
    (tmp_path / "spheres.csv").write_text(SPHERES)
    args = ("validate", "case.toml") if command == "validate" else ("run", "case.toml", "-o", "out", "-q")
    result = sphere_inproc(*args, cwd=tmp_path)
    assert_clean_error(result, 65, key, *fragments)
    assert not (tmp_path / "out").exists()


def test_an_approach_of_the_wall_a_grid_follows_is_warned_of_before_the_run(tmp_path):
    """A stage's `approach` moves the top wall at once, which a grid following it takes only
    below half a cell (else exit 70 when the stage begins, hours into a run): `validate` warns,
    naming the key and its line, and the case stays valid (an approach from near the bed is
    fine: tests/unit/test_cuda_dem.py runs one)."""
    text = edit(
        DARCY.replace('[[walls]]\nface = "z-"\n', '[[walls]]\nface = "z-"\n' + TOP_WALL),
        'model = "darcy"',
        'model = "darcy"\ngrid = { follow_top_wall = true }\n[[stages]]\nduration = 0.001\n'
        '[[stages.walls]]\nface = "z+"\nmode = "stress"\nstress = 100.0\napproach = true',
    )
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert result.code == 0, result.stderr
    warning = f"sphere: warning: case.toml:{line_of(text, 'approach = true')}: stages[0].walls[0].approach"
    assert warning in result.stderr and "the run stops (exit 70)" in result.stderr
