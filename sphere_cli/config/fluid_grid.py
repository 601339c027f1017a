"""The regular fluid grid shared by the 3D fluid models (`[fluid.grid]` of "navier-stokes" and
"darcy"): how many cells the domain box is cut into.

The grid spans the whole box: cell edge along an axis = box length / cells along it; with
`follow_top_wall` its top is instead the "z+" wall wherever that wall is, and its nz cells
stretch uniformly between the box bottom and the wall. What the porosity estimate needs
(physics/fluid/porosity.py), the smallest cell edge at least the largest particle diameter so
that the spherical sampling volume of a cell (diameter = the smallest cell edge) is never smaller
than a particle, is checked before the scene is built (config/consistency.py fluid_problems,
against a placement file's radii once read) and again when it is built (physics/fluid/grid.py).
"""

from __future__ import annotations

import math

import numpy as np
from pydantic import Field, model_validator

from .base import Count, Flag, Real, Strict

# cell edge chosen when neither `cells` nor `cell_size` is given, in largest particle diameters
AUTO_CELL_DIAMETERS = 3.0


class FluidGridConfig(Strict):
    """Cells of the fluid grid: give `cells` or `cell_size`, or neither for the automatic size."""

    cells: tuple[Count, Count, Count] | None = Field(
        None,
        description=(
            "Number of cells along x, y and z; the cell edge along an axis is the box length "
            "divided by this number. Exclusive with cell_size [-]."
        ),
    )
    cell_size: Real | None = Field(
        None,
        gt=0,
        description=(
            "Smallest acceptable cell edge: each axis gets floor(box length / cell_size) cells "
            "(at least one), so every edge is at least this long. Exclusive with cells. Neither "
            "given: three largest particle diameters. Whichever way, the smallest edge must be "
            "at least the largest particle diameter [m]."
        ),
    )

    follow_top_wall: Flag = Field(
        False,
        description=(
            'The grid\'s top is the "z+" wall and moves with it: the cells along z keep their '
            "number and stretch uniformly, dz = (z_wall - z_bottom) / nz, and the top boundary "
            'acts at the wall. Needs a "z+" wall; the run stops (exit 70) if dz falls below the '
            "largest particle diameter. Navier-Stokes: the top must be a pressure one. Darcy: "
            'the wall bounds the pore fluid, permeable with a "pressure" top (drained) or '
            'impermeable with a "no-flow" top (undrained: the pore pressure pushes the wall) [-].'
        ),
    )

    @model_validator(mode="after")
    def _one_way(self):
        if self.cells is not None and self.cell_size is not None:
            raise ValueError("give either cells or cell_size, not both")
        if self.cells is not None and min(self.cells) < 1:
            raise ValueError(f"cells must be at least 1 along every axis, got {list(self.cells)}")
        return self


def grid_cells(
    config: FluidGridConfig, length, diameter: float
) -> tuple[tuple[int, int, int], str, str | None]:
    """Cells per axis for a box of edge lengths `length` (3,) [m] and particles of largest
    diameter `diameter` [m]; the key that set them ("cells" or "cell_size"); and what is wrong
    with them for the porosity estimate (None when nothing is)."""
    if config.cells is not None:
        key = "cells"
        shape = tuple(int(n) for n in config.cells)
    else:
        key = "cell_size"
        size = config.cell_size if config.cell_size is not None else AUTO_CELL_DIAMETERS * diameter
        # a length that is a whole number of cells up to round-off gets that number; a cell_size
        # far below any particle (refused below) can overflow the float, capped at 2^62 cells
        ratios = (float(L) / size * (1.0 + 1e-12) for L in length)
        shape = tuple(max(1, math.floor(min(r, 2.0**62))) for r in ratios)
    edges = [float(L) / n for L, n in zip(length, shape, strict=True)]
    ax = min(range(3), key=lambda a: edges[a])
    problem = None
    if edges[ax] < diameter:
        problem = (
            f"cells of {edges[ax]:g} m along {'xyz'[ax]} are smaller than the largest particle "
            f"diameter {diameter:g} m; the porosity estimate needs every cell edge at least that "
            f"long (at most {math.floor(float(length[ax]) / diameter)} cells along {'xyz'[ax]})"
        )
    return shape, key, problem


def centres_along(origin: float, spacing: float, n: int) -> np.ndarray:
    """Coordinates of the n cell centres along one axis of a grid starting at `origin` with cells
    `spacing` long [m] (the grid's own, physics/fluid/grid.py FluidGrid.centres)."""
    return origin + (np.arange(n) + 0.5) * spacing


def grid_centres(lower, upper, shape) -> list[np.ndarray]:
    """The cell centres along x, y and z [m] of a grid of `shape` cells spanning the box from
    `lower` to `upper` (the grid's own spacing: box length / cells, in float64)."""
    origin = np.asarray(lower, dtype=np.float64)
    spacing = (np.asarray(upper, dtype=np.float64) - origin) / np.array(shape, dtype=np.float64)
    return [centres_along(origin[a], spacing[a], shape[a]) for a in range(3)]


def follow_problems(config: FluidGridConfig, case) -> list[tuple[tuple, str]]:
    """A grid following the top wall against the case's walls: it needs a "z+" wall."""
    faces = [wall.face for wall in case.walls]
    if not config.follow_top_wall or "z+" in faces:
        return []
    return [
        (
            ("fluid", "grid", "follow_top_wall"),
            'true needs a top wall to follow: add a [[walls]] entry with face = "z+" (walls now: '
            f"{', '.join(faces) or 'none'})",
        )
    ]


def follow_warnings(config: FluidGridConfig, case) -> list[tuple[tuple, str]]:
    """A stage's `approach` on the wall a grid follows moves it at once, and the grid follows a
    wall only as it moves less than half a cell a fluid step (its porosity rate, and a Darcy
    fluid's undrained push, are those of a small move): the run stops (exit 70) where the
    approach is longer, which is known only when the stage begins."""
    if not config.follow_top_wall:
        return []
    return [
        (
            ("stages", k, "walls", j, "approach"),
            "moves the z+ wall onto the particles at once, and the fluid grid follows that wall "
            "(fluid.grid.follow_top_wall) only by less than half a cell a fluid step: the run stops "
            "(exit 70) when the stage begins if the wall is further from the bed; a stress-driven "
            "wall moves down to the bed by itself",
        )
        for k, stage in enumerate(case.stages)
        for j, spec in enumerate(stage.walls)
        if spec.face == "z+" and spec.approach
    ]
