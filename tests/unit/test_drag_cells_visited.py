"""The cells a rank's particles can visit until the next list build (physics/fluid/drag.py
FluidParticleDrag._reachable_cells): on MPI ranks each rank sums the drag coefficients of those
cells only, for its particles' self-induced velocities, so a cell left out would give a kick
other than one rank's; when the plan of those sums is made again (plan_exchange), which rows it
sends to another rank and the order in which it sums its own and those it receives."""

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
    cells = drag._reachable_cells(types.SimpleNamespace(neighbors=neighbors))
    assert cells.shape[1] == len(ref)
    mask = np.zeros(int(np.prod(SHAPE)), dtype=bool)
    mask[cells.reshape(-1)] = True
    return mask


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


class Ranks:
    """The calls of physics/rank_steps.py EveryRank that the drag's sums make, for rank 0 of two:
    rank 1's particles visit cell `theirs` alone, and it sends the rows `arriving` (global
    index, cell, coefficient) of its own particles that can be in this rank's cells."""

    rank = 0

    def __init__(self, gid, theirs: int, arriving):
        self.held = np.asarray(gid)
        self.theirs = theirs
        self.arriving = arriving
        self.masks = 0
        self.sent = None

    def every_mask(self, mask):
        self.masks += 1
        other = np.zeros_like(mask)
        other[self.theirs] = True
        return np.packbits(np.stack([mask, other]), axis=1)

    def own(self):
        return np.arange(self.held.size)

    def gid(self):
        return self.held

    def alltoall(self, objects):
        assert objects[0] is None  # nothing to itself
        self.sent = objects[1]
        return [None, np.array([g for g, _, _ in self.arriving])]

    @staticmethod
    def boxes(send, receive, width):
        return {}, {}

    def swap(self, columns, send, receive, boxes):
        (table,) = columns
        assert list(send) == [1] and list(receive) == [1]
        for row, (_, cell, coef) in zip(receive[1], self.arriving, strict=True):
            table[row] = cell, coef


def test_the_plan_is_made_again_at_a_list_build():
    """The plan is made once a list build, not once a step."""
    grid = FluidGrid(origin=[0.0] * 3, spacing=SPACING, shape=SHAPE, periodic=[True, True, False])
    drag = FluidParticleDrag(DragConfig(), 1000.0, 1e-3, grid, 3, False)
    drag.whole = ranks = Ranks([0, 2, 4], theirs=5, arriving=[(3, 5, 0.5)])
    drag.cell_of[:] = [0, 5, 5]
    drag.coef[:] = [1.0, 2.0, 3.0]
    ref = [[0.2e-3, 0.2e-3, 0.2e-3], [0.2e-3, 0.2e-3, 2.7e-3], [0.2e-3, 0.2e-3, 2.8e-3]]
    neighbors = types.SimpleNamespace(ref_pos=np.array(ref), skin=1e-5, builds=4)
    state = types.SimpleNamespace(neighbors=neighbors)
    drag._cell_coefficients(state)
    drag._cell_coefficients(state)
    assert ranks.masks == 1
    assert drag.cell_coef[0] == 1.0 and drag.cell_coef[5] == 5.5
    neighbors.builds += 1
    drag._cell_coefficients(state)
    assert ranks.masks == 2


def test_a_grid_that_stretches_plans_by_columns_once_a_list_build():
    """A grid following the top wall stretches its cells along z at each fluid step, moving
    particles between cells without a build: the plan takes whole columns. Rank 1's particles
    visit column (0, 0) alone: this rank sends it both of its particles in that column, low and
    high (global 0 and 2), whichever cells the stretch puts them in, not the one in column
    (2, 0) (global 4); a stretch does not make the plan again, a build does."""
    grid = FluidGrid(origin=[0.0] * 3, spacing=SPACING, shape=SHAPE, periodic=[True, True, False])
    drag = FluidParticleDrag(DragConfig(), 1000.0, 1e-3, grid, 3, False)
    drag.stretches = True
    drag.whole = ranks = Ranks([0, 2, 4], theirs=0, arriving=[(3, 5, 0.5)])
    drag.cell_of[:] = [0, 5, (2 * 5 + 0) * 6 + 3]
    drag.coef[:] = [1.0, 2.0, 3.0]
    ref = [[0.2e-3, 0.2e-3, 0.2e-3], [0.2e-3, 0.2e-3, 2.7e-3], [2.5e-3, 0.2e-3, 1.7e-3]]
    neighbors = types.SimpleNamespace(ref_pos=np.array(ref), skin=1e-5, builds=4)
    state = types.SimpleNamespace(neighbors=neighbors)
    drag._cell_coefficients(state)
    assert list(ranks.sent) == [0, 2]
    assert drag.cell_coef[0] == 1.0 and drag.cell_coef[5] == 2.5 and drag.cell_coef[63] == 3.0
    drag.spacing[2] *= 1.01  # the grid's own array, stretched in place
    drag._cell_coefficients(state)
    assert ranks.masks == 1
    neighbors.builds += 1
    drag._cell_coefficients(state)
    assert ranks.masks == 2


def test_rows_go_to_the_ranks_whose_cells_they_can_reach_and_are_summed_in_global_order():
    """Rank 1's particles visit cell 5 only: this rank sends it its two particles there (global
    2 and 4), not the one in cell 0, and sums cell 5 over its own and rank 1's particle (global
    3) in global order. The sum 2^53 + 1 - 2^53 is 0 in that order (2^53 + 1 rounds to 2^53);
    its own rows first would give 1."""
    grid = FluidGrid(origin=[0.0] * 3, spacing=SPACING, shape=SHAPE, periodic=[True, True, False])
    drag = FluidParticleDrag(DragConfig(), 1000.0, 1e-3, grid, 3, False)
    drag.whole = ranks = Ranks([0, 2, 4], theirs=5, arriving=[(3, 5, 1.0)])
    drag.cell_of[:] = [0, 5, 5]
    drag.coef[:] = [1.0, 2.0**53, -(2.0**53)]
    ref = [[0.2e-3, 0.2e-3, 0.2e-3], [0.2e-3, 0.2e-3, 2.7e-3], [0.2e-3, 0.2e-3, 2.8e-3]]
    neighbors = types.SimpleNamespace(ref_pos=np.array(ref), skin=1e-5, builds=0)
    drag._cell_coefficients(types.SimpleNamespace(neighbors=neighbors))
    assert list(ranks.sent) == [2, 4]
    assert drag.cell_coef[0] == 1.0
    assert drag.cell_coef[5] == 0.0


def test_packed_masks_are_read_at_any_entry_as_unpacked():
    """Every rank's mask stays packed (EveryRank.every_mask): its entries read from the bits are
    those of the mask, for masks of a length no multiple of 8 and entries in any order."""
    rng = np.random.default_rng(3)
    masks = rng.random((3, 37)) < 0.4
    packed = np.packbits(masks, axis=1)
    index = rng.integers(0, 37, size=(4, 9))
    assert np.array_equal(FluidParticleDrag._marked(packed, index), masks[:, index])
    assert np.array_equal(FluidParticleDrag._marked(packed[1], index), masks[1][index])
