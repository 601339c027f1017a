"""Bad input to `[fluid.grid] follow_top_wall` (the fluid grid following the top wall): exit 65
naming the key and its line before anything runs; a wall that squeezes the cells below the
largest particle diameter during the run stops it (exit 70) naming the wall position and the cell
height, never a NaN."""

from __future__ import annotations

from cli_test_support import NAVIER_STOKES_SCENE, TINY, assert_clean_error, edit, line_of, sphere_inproc

# NAVIER_STOKES_SCENE: box 10 x 10 x 20 mm, 4 x 4 x 8 cells, particles 1 mm across up to z = 8 mm
FOLLOWING = edit(
    NAVIER_STOKES_SCENE + 'top = { type = "pressure" }\n',
    "grid = { cells = [4, 4, 8] }",
    "grid = { cells = [4, 4, 8], follow_top_wall = true }",
)
TOP_WALL = '[[walls]]\nface = "z+"\nmode = "velocity"\nvelocity = 10.0\n\n[fluid]'


def _run(tmp_path, text):
    (tmp_path / "case.toml").write_text(text)
    return sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)


def test_needs_a_top_wall(tmp_path):
    result = _run(tmp_path, FOLLOWING)
    line = line_of(FOLLOWING, "follow_top_wall")
    assert_clean_error(
        result, 65, "fluid.grid.follow_top_wall", f"case.toml:{line}:", 'face = "z+"', "walls now: z-"
    )
    assert not (tmp_path / "out").exists()


def test_needs_an_open_top(tmp_path):
    text = edit(FOLLOWING, "[fluid]", TOP_WALL)
    text = edit(text, 'top = { type = "pressure" }', 'top = { type = "no-flow" }')
    result = _run(tmp_path, text)
    assert_clean_error(result, 65, "fluid.top.type", f"case.toml:{line_of(text, 'top =')}:", '"no-flow"')


DARCY_FOLLOWING = TINY.replace(
    "[output.frames]",
    '[fluid]\nmodel = "darcy"\ntop = { type = "no-flow" }\n\n[fluid.grid]\ncells = [4, 4, 8]\n'
    "follow_top_wall = true\n\n[output.frames]",
)
DARCY_TOP_WALL = '[[walls]]\nface = "z+"\nmode = "velocity"\nvelocity = 50.0\n\n[fluid]'


def test_darcy_needs_a_top_wall(tmp_path):
    result = _run(tmp_path, DARCY_FOLLOWING)
    line = line_of(DARCY_FOLLOWING, "follow_top_wall")
    assert_clean_error(result, 65, "fluid.grid.follow_top_wall", f"case.toml:{line}:", 'face = "z+"')


def test_darcy_refuses_fixed_pressure_regions(tmp_path):
    """The cells move with the wall: a region of them given in the case would not stay put."""
    text = edit(DARCY_FOLLOWING, "[fluid]", DARCY_TOP_WALL)
    text = edit(
        text,
        "[output.frames]",
        "[[fluid.fixed_pressure]]\nlower = [0.0, 0.0, 0.0]\nupper = [0.01, 0.01, 0.005]\npressure = 10.0\n\n"
        "[output.frames]",
    )
    result = _run(tmp_path, text)
    assert_clean_error(result, 65, "fluid.fixed_pressure", "follow_top_wall")


def test_darcy_wall_squeezing_the_cells_below_a_particle_stops_the_run(tmp_path):
    """8 cells of 2.5 mm under a wall coming down at 50 m/s: after about 4 mm (0.08 ms) the
    cells are less than the largest particle (1.97 mm): exit 70 naming the cell height, before
    any value goes bad."""
    text = edit(DARCY_FOLLOWING, "[fluid]", DARCY_TOP_WALL)
    result = _run(tmp_path, text)
    assert_clean_error(
        result, 70, "fluid cells (fluid.grid.follow_top_wall, 8 along z)", "largest particle diameter 0.00197"
    )
    assert "nan" not in result.stderr.lower()


def test_cells_below_a_particle_at_the_start(tmp_path):
    text = edit(edit(FOLLOWING, "[fluid]", TOP_WALL), "cells = [4, 4, 8]", "cells = [4, 4, 24]")
    result = _run(tmp_path, text)
    assert_clean_error(result, 65, "fluid.grid.cells", "largest particle diameter 0.001 m")


def test_wall_squeezing_the_cells_below_a_particle_stops_the_run(tmp_path):
    """16 cells of 1.25 mm; the wall comes down at 10 m/s, so after about 4 mm the cells are
    less than the 1 mm particles: exit 70 naming the wall's z and the cell height, before any
    fluid value goes bad."""
    text = edit(edit(FOLLOWING, "[fluid]", TOP_WALL), "cells = [4, 4, 8]", "cells = [4, 4, 16]")
    text = edit(text, "duration = 0.0005", "duration = 0.001")
    result = _run(tmp_path, text)
    assert_clean_error(
        result,
        70,
        "the top wall at z = 0.01599",
        "fluid cells (fluid.grid.follow_top_wall, 16 along z) 0.00099",
        "largest particle diameter 0.001 m",
    )
    assert "nan" not in result.stderr.lower()
