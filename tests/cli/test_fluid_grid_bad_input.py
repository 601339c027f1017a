"""Bad `[fluid.grid]` input (config/fluid_grid.py): a short message naming the key and its line,
exit 65, no traceback. Shown with the Darcy model, whose grid is the shared FluidGridConfig."""

from __future__ import annotations

import pytest
from cli_test_support import (
    FROM_FILE,
    TINY,
    TWO_SPHERES_CSV,
    assert_clean_error,
    edit,
    line_of,
    sphere_inproc,
)

# TINY: box 10 x 10 x 20 mm, radii up to 1 mm (largest diameter 2 mm)
DARCY = TINY.replace(
    "[output.frames]", '[fluid]\nmodel = "darcy"\n\n[fluid.grid]\ncells = [4, 4, 8]\n\n[output.frames]'
)

CASE_ERRORS = [
    # (id, replacement of "cells = [4, 4, 8]", key named, text on the line named, other fragments)
    (
        "cells-smaller-than-a-particle",
        "cells = [4, 4, 12]",
        "fluid.grid.cells",
        "cells =",
        ["cells of 0.00166667 m along z", "largest particle diameter 0.002 m", "at most 10 cells along z"],
    ),
    (
        "cell-size-smaller-than-a-particle",
        "cell_size = 0.0015",
        "fluid.grid.cell_size",
        "cell_size =",
        ["largest particle diameter 0.002 m"],
    ),
    (
        "both-ways",
        "cells = [4, 4, 8]\ncell_size = 0.002",
        "fluid.grid",
        "[fluid.grid]",
        ["either cells or cell_size"],
    ),
    ("zero-cells", "cells = [4, 0, 8]", "fluid.grid", "[fluid.grid]", ["at least 1"]),
    ("typo", "cels = [4, 4, 8]", "fluid.grid.cels", "cels =", ["unknown key"]),
]


@pytest.mark.parametrize(
    ("new", "key", "marker", "fragments"),
    [c[1:] for c in CASE_ERRORS],
    ids=[c[0] for c in CASE_ERRORS],
)
def test_grid_error_names_key_and_line(tmp_path, new, key, marker, fragments):
    text = edit(DARCY, "cells = [4, 4, 8]", new)
    case = tmp_path / "case.toml"
    case.write_text(text)
    result = sphere_inproc("validate", case)
    assert_clean_error(result, 65, key, f"case.toml:{line_of(text, marker)}:", *fragments)


def test_radii_from_a_file_are_checked_when_the_scene_is_built(tmp_path):
    """Radii read from a placement file are known only to the builder: `run` refuses the grid
    before the first step (two spheres of diameter 2 mm; 8 cells of 1.25 mm along each axis)."""
    text = FROM_FILE + '\n[fluid]\nmodel = "darcy"\n\n[fluid.grid]\ncells = [8, 8, 8]\n'
    (tmp_path / "case.toml").write_text(text)
    (tmp_path / "spheres.csv").write_text(TWO_SPHERES_CSV)
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(
        result,
        65,
        "fluid.grid.cells",
        f"case.toml:{line_of(text, 'cells =')}:",
        "cells of 0.00125 m along x are smaller than the largest particle diameter 0.002 m",
    )
