"""The regular cell-centred fluid grid of the 3D fluid models, made from `[fluid.grid]`
(config/fluid_grid.py) and the domain box.

Cell (i, j, k) spans origin + (i, j, k) * spacing to origin + (i+1, j+1, k+1) * spacing; its
centre is at origin + (i + 1/2, j + 1/2, k + 1/2) * spacing. Fields on the grid are arrays of
shape (nx, ny, nz) (scalars) or (nx, ny, nz, 3) (vectors), C order.

A grid that follows the top wall (`[fluid.grid] follow_top_wall`) keeps its cells along z and
changes its height: `set_height` rewrites spacing[2] in place, so every holder of the spacing
array sees the new cells; what a holder derives from it (the pressure solver's 1/h^2, the drag's
cell volume) it refreshes when told (physics/fluid/navier_stokes.py).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...config.fluid_grid import FluidGridConfig, centres_along, grid_cells
from ...errors import NumericalError


@dataclass(frozen=True)
class FluidGrid:
    origin: np.ndarray  # (3,) [m] lower corner of the grid (= the domain box's)
    spacing: np.ndarray  # (3,) [m] cell edges dx, dy, dz
    shape: tuple[int, int, int]  # (nx, ny, nz)
    periodic: np.ndarray  # (3,) bool, as the domain box

    def __post_init__(self):
        # one float64 array per grid, shared (not copied) by whoever takes np.asarray of it
        object.__setattr__(self, "spacing", np.asarray(self.spacing, dtype=np.float64))

    @property
    def height(self) -> float:
        """Extent along z, nz dz [m]."""
        return float(self.shape[2] * self.spacing[2])

    def set_height(self, height: float) -> None:
        """Stretch the cells along z so that the grid spans `height` [m] from its origin."""
        self.spacing[2] = height / self.shape[2]

    @property
    def cell_volume(self) -> float:
        """[m^3]"""
        return float(np.prod(self.spacing))

    @property
    def cell_count(self) -> int:
        return int(np.prod(self.shape))

    @property
    def sampling_radius(self) -> float:
        """Radius of the cell-centred spherical volume the porosity is sampled in: half the
        smallest cell edge (sphere-fluid-particle-interaction.md, "Porosity estimation") [m]."""
        return 0.5 * float(self.spacing.min())

    def centres(self, axis: int) -> np.ndarray:
        """Coordinates of the cell centres along one axis (0, 1, 2) [m]."""
        return centres_along(self.origin[axis], self.spacing[axis], self.shape[axis])

    def describe(self) -> str:
        nx, ny, nz = self.shape
        dx, dy, dz = self.spacing
        return f"{nx} x {ny} x {nz} cells of {dx:.4g} x {dy:.4g} x {dz:.4g} m"


def fluid_grid(config: FluidGridConfig, box, radius: np.ndarray, loaded=None) -> FluidGrid:
    """The grid over the domain box (state.box: lower, upper, periodic) for particles of these
    radii [m]. A grid that breaks what the porosity estimate needs (smallest cell edge at least
    the largest particle diameter) is refused: with `loaded` (the LoadedCase) as its error naming
    the key under [fluid.grid] (exit 65), without it as a ValueError."""

    lower = np.asarray(box.lower, dtype=np.float64)
    length = np.asarray(box.upper, dtype=np.float64) - lower
    diameter = 2.0 * float(np.max(radius)) if len(radius) else 0.0
    shape, key, problem = grid_cells(config, length, diameter)
    if problem is not None:
        if loaded is not None:
            raise loaded.error(("fluid", "grid", key), problem)
        raise ValueError(f"fluid.grid.{key}: {problem}")
    spacing = length / np.array(shape, dtype=np.float64)
    return FluidGrid(
        origin=lower.copy(),
        spacing=spacing,
        shape=shape,
        periodic=np.asarray(box.periodic, dtype=bool).copy(),
    )


def top_wall_index(state) -> int:
    """Index of the "z+" wall that a grid with `[fluid.grid] follow_top_wall` follows (a case
    without one is refused before the scene is built: config/fluid_grid.py follow_problems)."""
    return state.walls.faces.index("z+")


def wall_cells(state, wall: int, nz: int, height: float, diameter: float) -> str:
    """Where the cells of a grid following the top wall stand when the wall puts its top
    `height` [m] above the grid's bottom, as the start of a stop message; stops (exit 70) here if
    they would be lower than the largest particle `diameter` [m] that the porosity estimate
    needs."""
    clock, dz = state.clock, height / nz
    where = (
        f"step {clock.step} (t = {clock.time:.6g} s): the top wall at z = "
        f"{float(state.walls.coord[wall]):.7g} m makes the fluid cells (fluid.grid."
        f"follow_top_wall, {nz} along z) {dz:.6g} m high"
    )
    if not dz >= diameter:
        raise NumericalError(
            f"{where}, less than the largest particle diameter {diameter:.4g} m that the porosity "
            "estimate needs; use fewer cells along z or stop the wall higher"
        )
    return where
