"""Bad input to the drag of the Navier-Stokes fluid (`[fluid.drag]`): a short message naming the
TOML key and line, exit 65, no traceback; and the porosity floor warning names the cell."""

from __future__ import annotations

import pytest
from cli_test_support import NAVIER_STOKES_SCENE, assert_clean_error, edit, line_of, sphere_inproc

CASE = (
    'title = "drag"\n\n'
    + NAVIER_STOKES_SCENE
    + """
[fluid.drag]
law = "gidaspow"
pressure_force = true
porosity_floor = 0.1
"""
)

# (id, text to replace, replacement, key named, text on the line named, other fragments)
ERRORS = [
    (
        "law",
        'law = "gidaspow"',
        'law = "stokes"',
        "fluid.drag.law",
        'law = "stokes"',
        ["gidaspow", "di-felice"],
    ),
    (
        "floor-at-1",
        "porosity_floor = 0.1",
        "porosity_floor = 1.0",
        "fluid.drag.porosity_floor",
        "porosity_floor",
        [],
    ),
    (
        "floor-zero",
        "porosity_floor = 0.1",
        "porosity_floor = 0",
        "fluid.drag.porosity_floor",
        "porosity_floor",
        [],
    ),
    (
        "flag-as-number",
        "pressure_force = true",
        "pressure_force = 1",
        "fluid.drag.pressure_force",
        "pressure_",
        [],
    ),
    (
        "self-induced-value",
        "porosity_floor = 0.1",
        'porosity_floor = 0.1\nself_induced = "remove"',
        "fluid.drag.self_induced",
        "self_induced",
        ["subtract", "keep"],
    ),
    (
        "self-induced-with-cell-averaging",
        "porosity_floor = 0.1",
        'porosity_floor = 0.1\naveraging = "cell"\nself_induced = "subtract"',
        "fluid.drag",
        "[fluid.drag]",
        ['averaging = "particle"'],
    ),
    (
        "typo",
        "pressure_force = true",
        "pressure_forces = true",
        "fluid.drag.pressure_forces",
        "pressure_",
        ["unknown key"],
    ),
]


@pytest.mark.parametrize(
    ("old", "new", "key", "marker", "fragments"), [e[1:] for e in ERRORS], ids=[e[0] for e in ERRORS]
)
def test_drag_error_names_key_and_line(tmp_path, old, new, key, marker, fragments):
    text = edit(CASE, old, new)
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("validate", tmp_path / "case.toml")
    assert_clean_error(result, 65, key, f"case.toml:{line_of(text, marker)}:", *fragments)


def test_drag_defaults_in_the_resolved_case(tmp_path):
    """Without a [fluid.drag] table the resolved case shows the defaults."""
    text = CASE[: CASE.index("[fluid.drag]")]
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("validate", tmp_path / "case.toml")
    assert result.code == 0, result.stderr
    for fragment in ("gidaspow", "pressure_force", "porosity_floor", "self_induced", "subtract"):
        assert fragment in result.stdout
