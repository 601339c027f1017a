"""The cells a rank's particles can visit until the next list build (physics/fluid/drag.py
FluidParticleDrag._cells_visited): on MPI ranks each rank sums the drag coefficients of those
cells only, for its particles' self-induced velocities, so a cell left out would give a kick
other than one rank's."""

from __future__ import annotations

import itertools
import types

import numpy as np

from sphere_cli.config.drag import DragConfig
from sphere_cli.physics.fluid.drag import FluidParticleDrag
from sphere_cli.physics.fluid.grid import FluidGrid

SPACING = np.array([1.0e-3, 1.0e-3, 0.5e-3])
SHAPE = (4, 5, 6)


def visited(ref: np.ndarray, skin: float) -> np.ndarray:
    grid = FluidGrid(origin=[0.0] * 3, spacing=SPACING, shape=SHAPE, periodic=[True, True, False])
    drag = FluidParticleDrag(DragConfig(), 1000.0, 1e-3, grid, len(ref), False)
    neighbors = types.SimpleNamespace(ref_pos=np.asarray(ref, dtype=np.float64), skin=skin)
    return drag._cells_visited(types.SimpleNamespace(neighbors=neighbors))


def cells_of_box(centre, half: float) -> set:
    """The cells a fine lattice of points over the box centre +- half lies in (periodic x and
    y wrapped, z clamped to the grid, as bin_particles does)."""
    out = set()
    for offset in itertools.product(np.linspace(-half, half, 41), repeat=3):
        x = np.asarray(centre) + offset
        i = [int(np.floor(x[a] / SPACING[a])) for a in range(3)]
        i[0] %= SHAPE[0]
        i[1] %= SHAPE[1]
        i[2] = min(max(i[2], 0), SHAPE[2] - 1)
        out.add((i[0] * SHAPE[1] + i[1]) * SHAPE[2] + i[2])
    return out


def test_a_particle_near_cell_faces_reaches_the_cells_beyond_them_wrapped_and_clamped():
    """Half the skin (0.1 mm) over an x face, across the periodic y = 0 face and under the
    grid's bounded bottom: the 2 x 2 x 1 cells it can reach, no more."""
    mask = visited([[0.95e-3, 0.05e-3, 0.02e-3]], skin=0.2e-3)
    assert set(np.flatnonzero(mask)) == cells_of_box([0.95e-3, 0.05e-3, 0.02e-3], 0.1e-3)
    assert np.count_nonzero(mask) == 4
    assert mask[(0 * 5 + 4) * 6 + 0] and mask[(1 * 5 + 0) * 6 + 0]  # x 0 and 1; y wrapped to 4


def test_a_skin_wider_than_the_cells_reaches_every_cell_between():
    """Half the skin (1.3 mm) spans more than two cells along every axis: the cells between the
    box's corners are reached too, for particles anywhere."""
    rng = np.random.default_rng(7)
    ref = rng.uniform([0.0, 0.0, 0.0], [4e-3, 5e-3, 3e-3], size=(5, 3))
    mask = visited(ref, skin=2.6e-3)
    expected = set().union(*(cells_of_box(r, 1.3e-3) for r in ref))
    assert set(np.flatnonzero(mask)) == expected
    assert np.count_nonzero(mask) < mask.size  # not every cell: the bound is tested


def test_no_particles_visit_no_cells():
    assert not visited(np.zeros((0, 3)), skin=1e-4).any()
