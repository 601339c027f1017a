"""The fluid grid over the domain box (config/fluid_grid.py, physics/fluid/grid.py): cell counts
from `cells` or `cell_size`, and the refusal of cells smaller than the largest particle, which
the porosity estimate needs (its sampling sphere has the diameter of the smallest cell edge)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from pydantic import ValidationError

from sphere_cli.config.fluid_grid import FluidGridConfig
from sphere_cli.config.load import LoadedCase
from sphere_cli.errors import CaseError
from sphere_cli.physics.fluid.grid import fluid_grid

BOX = SimpleNamespace(
    lower=np.array([0.0, -0.01, 0.0]),
    upper=np.array([0.04, 0.01, 0.06]),
    periodic=np.array([1, 1, 0], dtype=np.uint8),
)
RADII = np.array([0.001, 0.0015, 0.0012])  # largest diameter 3 mm


def test_cells_per_axis():
    grid = fluid_grid(FluidGridConfig(cells=(8, 4, 12)), BOX, RADII)
    assert grid.shape == (8, 4, 12)
    assert np.allclose(grid.spacing, [0.005, 0.005, 0.005])
    assert np.array_equal(grid.origin, BOX.lower)
    assert grid.periodic.tolist() == [True, True, False]
    assert grid.sampling_radius == pytest.approx(0.0025)
    assert grid.centres(2)[0] == pytest.approx(0.0025)
    assert grid.cell_volume == pytest.approx(0.005**3)


def test_cell_size_gives_the_largest_count_with_edges_at_least_that_long():
    grid = fluid_grid(FluidGridConfig(cell_size=0.0045), BOX, RADII)
    assert grid.shape == (8, 4, 13)  # 0.04/0.0045 = 8.9, 0.02/0.0045 = 4.4, 0.06/0.0045 = 13.3
    assert grid.spacing.min() >= 0.0045
    # a box that is a whole number of cells up to round-off gets that number
    assert fluid_grid(FluidGridConfig(cell_size=0.02 / 3), BOX, RADII).shape[1] == 3


def test_automatic_cell_size_is_three_largest_diameters():
    grid = fluid_grid(FluidGridConfig(), BOX, RADII)
    assert grid.shape == (4, 2, 6)  # 9 mm cells


def test_both_ways_at_once_is_refused():
    with pytest.raises(ValidationError, match="either cells or cell_size"):
        FluidGridConfig(cells=(2, 2, 2), cell_size=0.01)
    with pytest.raises(ValidationError):
        FluidGridConfig(cells=(2, 0, 2))
    with pytest.raises(ValidationError):
        FluidGridConfig(cell_size=-1.0)
    with pytest.raises(ValidationError):
        FluidGridConfig(cells=(2, 2, 2), spacing=0.1)  # extra keys are errors


def test_cells_smaller_than_a_particle_are_refused_naming_the_key():
    with pytest.raises(ValueError, match=r"fluid\.grid\.cells: cells of 0.002 m along y are smaller"):
        fluid_grid(FluidGridConfig(cells=(8, 10, 12)), BOX, RADII)
    text = "[fluid]\nmodel = 'darcy'\n[fluid.grid]\ncell_size = 0.001\n"
    loaded = LoadedCase(case=None, text=text, path=None)
    with pytest.raises(CaseError) as info:
        fluid_grid(FluidGridConfig(cell_size=0.001), BOX, RADII, loaded=loaded)
    message = str(info.value)
    assert message.startswith("<case>:4: fluid.grid.cell_size = 0.001: cells of 0.001 m along x")
    assert "largest particle diameter 0.003 m" in message and "at most 13 cells along x" in message
    assert info.value.exit_code == 65


def test_case_check_applies_the_same_rule_before_anything_is_built():
    """config/consistency.py refuses the grid for the largest particle diameter it is given
    (the radius distribution's, or a placement file's once `sphere validate` has read it); with
    the file not read (None), only what the case's own keys decide."""
    from sphere_cli.config.consistency import fluid_problems
    from sphere_cli.config.schema import Case

    case = Case.model_validate(
        {
            "simulation": {"duration": 0.01},
            "domain": {"upper": [0.04, 0.02, 0.06]},
            "particles": {"count": 10, "density": 2500.0},
            "contact": {"normal_stiffness": 1e4},
            "fluid": {"model": "darcy", "grid": {"cells": [8, 10, 12]}},
        }
    )
    [(key, message)] = fluid_problems(case, 0.003, 10)
    assert key == ("fluid", "grid", "cells") and "smaller than the largest particle diameter" in message
    assert fluid_problems(case, 0.002, 10) == []
    assert fluid_problems(case, None, None) == []
    assert fluid_problems(case.model_copy(update={"fluid": None}), 0.003, 10) == []
