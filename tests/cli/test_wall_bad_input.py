"""Bad wall modes, stages and particle groups: a message naming the TOML key and line, exit 65,
no traceback (validated in-process; nothing is run)."""

from __future__ import annotations

import pytest
from cli_test_support import TINY, assert_clean_error, edit, line_of, sphere_inproc

TOP = '[[walls]]\nface = "z-"'  # the floor of TINY, where each case appends its tables

# (id, text appended after the floor, key named, text on the line named, other fragments)
CASES = [
    (
        "fixed-with-stress",
        'mode = "fixed"\nstress = 1000.0',
        "walls[0].stress",
        "stress =",
        ['only for mode = "stress"', 'mode = "fixed"'],
    ),
    (
        "velocity-without-velocity",
        'mode = "velocity"',
        "walls[0].velocity",
        "[[walls]]",
        ["required key is missing"],
    ),
    (
        "stress-with-velocity",
        'mode = "stress"\nstress = 1000.0\nvelocity = 0.1',
        "walls[0].velocity",
        "velocity = 0.1",
        ['only for mode = "velocity"'],
    ),
    (
        "stress-without-stress",
        'mode = "stress"',
        "walls[0].stress",
        "[[walls]]",
        ["required key is missing"],
    ),
    (
        "sine-without-frequency",
        'mode = "stress"\nstress = 1000.0\nstress_amplitude = 100.0',
        "walls[0].stress_amplitude",
        "stress_amplitude",
        ["needs frequency as well"],
    ),
    (
        "shear-velocity-and-stress",
        'shear_axis = "x"\nshear_velocity = 0.1\nshear_stress = 10.0',
        "walls[0].shear_stress",
        "shear_stress",
        ["contradicts shear_velocity"],
    ),
    (
        "shear-along-own-axis",
        'shear_axis = "z"\nshear_velocity = 0.1',
        "walls[0].shear_axis",
        "shear_axis",
        ["must be tangential"],
    ),
    (
        "shear-without-axis",
        "shear_velocity = 0.1",
        "walls[0].shear_axis",
        "[[walls]]",
        ["required key is missing"],
    ),
    (
        "mass-on-fixed-wall",
        "mass = 0.1",
        "walls[0].mass",
        "mass =",
        ["only for a stress-driven wall"],
    ),
    (
        "stage-without-stop-condition",
        '[[stages]]\nname = "forever"',
        "stages[0]",
        "[[stages]]",
        ["needs a stop condition"],
    ),
    (
        "stage-stop-when-empty",
        "[[stages]]\nstop_when = { min_time = 0.1 }",
        "stages[0]",
        "[[stages]]",
        ["needs a stop condition"],
    ),
    (
        "stage-displacement-without-wall",
        "[[stages]]\nstop_when = { displacement = 0.001 }",
        "stages[0].stop_when.wall",
        "stop_when",
        ["required key is missing"],
    ),
    (
        "stage-wall-without-wall",
        '[[stages]]\nduration = 0.001\n[[stages.walls]]\nface = "z+"\nmode = "velocity"\nvelocity = 0.1',
        "stages[0].walls[0].face",
        'face = "z+"',
        ["no wall on this face"],
    ),
    (
        "stage-stress-on-periodic-axis",
        '[[stages]]\nduration = 0.001\n[[stages.walls]]\nface = "x-"\nmode = "stress"\nstress = 1000.0',
        "stages[0].walls[0].face",
        'face = "x-"',
        ["axis x is periodic", "cannot have stress control"],
    ),
    (
        "stage-contradictory-mode",
        '[[stages]]\nduration = 0.001\n[[stages.walls]]\nface = "z-"\nmode = "velocity"\nstress = 1.0',
        "stages[0].walls[0].stress",
        "stress = 1.0",
        ['only for mode = "stress"'],
    ),
    (
        "group-velocity-missing",
        "[[particles.groups]]\nregion_lower = [0, 0, 0]\nregion_upper = [0.01, 0.01, 0.002]\n"
        'motion = "velocity"',
        "particles.groups[0].velocity",
        "[[particles.groups]]",
        ["required key is missing"],
    ),
]


@pytest.mark.parametrize(("key_id", "extra", "key", "marker", "fragments"), CASES, ids=[c[0] for c in CASES])
def test_wall_and_stage_errors_name_key_and_line(tmp_path, key_id, extra, key, marker, fragments):
    text = edit(TINY, TOP, f"{TOP}\n{extra}")
    if key_id == "stage-stress-on-periodic-axis":
        text = edit(
            text, "upper = [0.01, 0.01, 0.02]", "upper = [0.01, 0.01, 0.02]\nperiodic = [true, false, false]"
        )
    case = tmp_path / "case.toml"
    case.write_text(text)
    result = sphere_inproc("validate", case)
    assert_clean_error(result, 65, key, f"case.toml:{line_of(text, marker)}:", *fragments)


def test_stress_wall_on_periodic_axis_is_refused(tmp_path):
    text = edit(
        TINY, "upper = [0.01, 0.01, 0.02]", "upper = [0.01, 0.01, 0.02]\nperiodic = [false, false, true]"
    )
    text = edit(text, TOP, f'{TOP}\nmode = "stress"\nstress = 1000.0')
    case = tmp_path / "case.toml"
    case.write_text(text)
    result = sphere_inproc("validate", case)
    assert_clean_error(result, 65, "walls[0].face", "axis z is periodic", "cannot have stress control")
