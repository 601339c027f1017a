"""Where a scene split across MPI ranks cuts its slabs or pencils (physics/rank_steps.py
RankSteps._cut), by particles held or, with simulation.rank_balance = "time", by each rank's
measured force time per particle. Run in one process: a stand-in for the MPI world adds the
other ranks' counts."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from sphere_cli.physics.rank_steps import RankSteps


class TwoRanks:
    """Rank 0 of two (or `size`), whose Allreduce(SUM) adds the other ranks' contribution
    `other`."""

    rank = 0

    def __init__(self, other: np.ndarray, size: int = 2):
        self.comm, self.mpi, self.other, self.size = self, SimpleNamespace(SUM="sum"), other, size

    def Allreduce(self, send, receive, op):  # noqa: N802 (mpi4py's name)
        receive[...] = send + self.other


def template(balance: str, cells=(10, 1, 1), size: int = 2, periodic=(False,) * 3) -> SimpleNamespace:
    """What _cut reads of the template: unit cells from the origin."""
    cells = np.array(cells)
    axes = tuple(a for a in range(3) if cells[a] >= 2)
    periodic = np.array(periodic)
    return SimpleNamespace(
        axes=axes, lower=np.zeros(3), cell=np.ones(3), cells=cells, periodic=periodic, balance=balance
    )


def slabs(balance: str, other: np.ndarray) -> tuple[np.ndarray, float]:
    """The slabs rank 0 cuts for 10 cells along x when it sends 100 particles in each of cells
    0-4, holding 600 with its ghosts and having spent 0.6 s in its forces; and its timer after."""
    steps = RankSteps(TwoRanks(other), template(balance))
    steps.part = SimpleNamespace(gid=np.arange(600))
    steps.busy = 0.6
    x = np.repeat(np.arange(5), 100) + 0.5
    steps._cut(np.stack((x, np.full(500, 0.5), np.full(500, 0.5)), axis=1))
    ((axis, bounds),) = steps.cut
    assert axis == 0
    return bounds, steps.busy


def test_slabs_share_the_particles_held():
    """The other rank sends 100 particles in each of cells 5-9: the cut is in the middle."""
    cut, _ = slabs("particles", np.r_[np.zeros(5), np.full(5, 100.0)])
    assert list(cut) == [0, 5, 10]


def test_slabs_share_the_measured_work():
    """The other rank took 3 ms a particle against this rank's 1 ms (0.6 s / 600): its cells
    weigh three times as much (work 0.1 s a cell here, 0.3 s there), and the cut moves to cell 7,
    where the larger slab's work, ghosts counted, is least (1.4 s against 1.2 s; at 6: 1.1 and
    1.5). The timer starts again."""
    cut, busy = slabs("time", np.r_[np.zeros(5), np.full(5, 100 * 3e-3)])
    assert list(cut) == [0, 7, 10]
    assert busy == 0.0


def test_a_bed_in_a_tall_box_is_cut_across_its_width():
    """A bed 10 cells wide and 4 deep in a box 40 cells tall, 25 particles in each cell: cut
    through its layers (z, the axis with the most cells), each rank would hold three of the four
    (own and ghosts, 750 particles); cut across its width (x), six of the ten columns (600).
    So x, even where the other rank held the cut axis before; its slabs halve the columns."""
    x, z = np.meshgrid(np.arange(10) + 0.5, np.arange(4) + 0.5, indexing="ij")
    ref = np.repeat(np.stack((x.ravel(), np.full(40, 0.5), z.ravel()), axis=1), 25, axis=0)
    steps = RankSteps(TwoRanks(np.zeros(10 + 40)), template("particles", cells=(10, 1, 40)))
    steps.cut = ((2, np.array([0, 2, 40])),)
    steps._cut(ref)
    ((axis, bounds),) = steps.cut
    assert axis == 0 and list(bounds) == [0, 5, 10]
    assert list(np.bincount(steps._owners(steps._cut_cells(ref))[0])) == [500, 500]


def test_a_tie_keeps_the_axis_of_the_last_cut():
    """A cube of 8 x 8 x 8 cells filled evenly holds as much cut along any axis: the last cut's
    axis (y) stays."""
    grid = np.stack(np.meshgrid(*(np.arange(8) + 0.5,) * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    steps = RankSteps(TwoRanks(np.zeros(24)), template("particles", cells=(8, 8, 8)))
    steps.cut = ((1, np.array([0, 3, 8])),)
    steps._cut(grid)
    ((axis, bounds),) = steps.cut
    assert axis == 1 and list(bounds) == [0, 4, 8]


def square_bed(periodic: bool) -> tuple[RankSteps, np.ndarray]:
    """Rank 0 of four, cutting a bed of 8 x 8 cells in x and y, one deep, 10 particles in each
    cell (all sent by rank 0)."""
    x, y = np.meshgrid(np.arange(8) + 0.5, np.arange(8) + 0.5, indexing="ij")
    ref = np.repeat(np.stack((x.ravel(), y.ravel(), np.full(64, 0.5)), axis=1), 10, axis=0)
    period = (periodic, periodic, False)
    steps = RankSteps(TwoRanks(np.zeros(8 + 8 + 64), size=4), template("particles", (8, 8, 1), 4, period))
    steps._cut(ref)
    return steps, ref


def test_four_ranks_cut_a_square_bed_into_pencils_where_they_hold_fewer():
    """Walled: four slabs of two columns hold up to four columns with their ghosts (320
    particles); pencils of 4 x 4 cells, each at a corner, hold 5 x 5 cells (250). Each rank owns
    a quarter; a particle at a block's corner is held by all four."""
    steps, ref = square_bed(periodic=False)
    assert [(axis, list(bounds)) for axis, bounds in steps.cut] == [(0, [0, 4, 8]), (1, [0, 4, 8])]
    owner, holders = steps._owners(steps._cut_cells(ref))
    assert list(np.bincount(owner)) == [160] * 4
    assert holders.shape == (9, 640)
    held = [int((holders == r).any(axis=0).sum()) for r in range(4)]
    assert held == [250] * 4
    corner = (np.abs(ref[:, 0] - 3.5) < 0.1) & (np.abs(ref[:, 1] - 3.5) < 0.1)
    assert all(set(holders[:, i]) == {0, 1, 2, 3} for i in np.flatnonzero(corner))


def test_periodic_axes_keep_slabs_where_pencils_hold_more():
    """Periodic in x and y: a pencil's ghosts wrap around on every side (6 x 6 cells, 360
    particles) while a slab holds four of the eight columns (320): slabs."""
    steps, _ = square_bed(periodic=True)
    assert len(steps.cut) == 1 and list(steps.cut[0][1]) == [0, 2, 4, 6, 8]


def test_more_ranks_than_cells_along_any_axis_are_cut_into_pencils():
    """Four ranks over a bed of 3 x 3 cells: no axis has a cell for each rank, pencils of 2 x 2
    do (blocks of 2 or 1 cells along each axis)."""
    x, y = np.meshgrid(np.arange(3) + 0.5, np.arange(3) + 0.5, indexing="ij")
    ref = np.stack((x.ravel(), y.ravel(), np.full(9, 0.5)), axis=1)
    steps = RankSteps(TwoRanks(np.zeros(3 + 3 + 9), size=4), template("particles", (3, 3, 1), 4))
    steps._cut(ref)
    assert [axis for axis, _ in steps.cut] == [0, 1]
    assert sorted(set(steps._owners(steps._cut_cells(ref))[0])) == [0, 1, 2, 3]


def test_the_last_cut_stays_unless_another_holds_two_per_cent_fewer():
    """Rows of 10 cells, 100 particles a cell but more in the two middle rows, on two ranks cut
    along y before: slabs along x hold 6/10 of the bed, slabs along y 1 % more (8 more a middle
    cell), then 5 % more (40 more). Only the second moves the cut to x: each change moves most
    particles between ranks."""
    for extra, axis in ((8, 1), (40, 0)):
        counts = np.full((10, 10), 100)
        counts[:, 4:6] += extra
        x, y = np.nonzero(counts)
        ref = np.repeat(np.stack((x + 0.5, y + 0.5, np.full(100, 0.5)), axis=1), counts.ravel(), axis=0)
        steps = RankSteps(TwoRanks(np.zeros(10 + 10)), template("particles", (10, 10, 1)))
        steps.cut = ((1, np.array([0, 5, 10])),)
        steps._cut(ref)
        assert steps.cut[0][0] == axis, extra


class Counting(TwoRanks):
    """TwoRanks that records the length of each Allreduce."""

    def __init__(self, size: int):
        super().__init__(0.0, size)
        self.sent: list[int] = []

    def Allreduce(self, send, receive, op):  # noqa: N802 (mpi4py's name)
        self.sent.append(send.size)
        super().Allreduce(send, receive, op)


def test_a_huge_sparse_box_sums_its_pencil_counts_only_where_no_slabs_fit():
    """1000 x 1000 cells: where slabs fit (4 ranks along x or y), the cut sums the counts of each
    axis alone, not the million cells of the pair; with 2000 ranks no axis has a cell for each,
    and the pencils' counts are summed."""
    ref = np.array([[0.5, 0.5, 0.5], [999.5, 999.5, 0.5]])
    for size, sent in ((4, 2000), (2000, 2000 + 1000 * 1000)):
        world = Counting(size)
        steps = RankSteps(world, template("particles", (1000, 1000, 1), size))
        steps._cut(ref)
        assert world.sent == [sent]
        assert len(steps.cut) == (1 if size == 4 else 2)
