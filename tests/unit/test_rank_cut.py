"""Where a scene split across MPI ranks cuts its slabs (physics/rank_steps.py RankSteps._cut),
by particles held or, with simulation.rank_balance = "time", by each rank's measured force time
per particle. Run in one process: a stand-in for the MPI world adds the other rank's counts."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np

from sphere_cli.physics.rank_steps import RankSteps


class TwoRanks:
    """Rank 0 of two, whose Allreduce(SUM) adds the other rank's contribution `other`."""

    size, rank = 2, 0

    def __init__(self, other: np.ndarray):
        self.comm, self.mpi, self.other = self, SimpleNamespace(SUM="sum"), other

    def Allreduce(self, send, receive, op):  # noqa: N802 (mpi4py's name)
        receive[...] = send + self.other


def template(balance: str, cells=(10, 1, 1)) -> SimpleNamespace:
    """What _cut reads of the template: unit cells from the origin, no axis periodic."""
    cells = np.array(cells)
    axes = tuple(a for a in range(3) if cells[a] >= 2)
    periodic = np.zeros(3, dtype=bool)
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
    return steps.slabs, steps.busy


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
    steps.axis = 2
    steps._cut(ref)
    assert steps.axis == 0
    assert list(steps.slabs) == [0, 5, 10]
    assert list(np.bincount(steps._owners(steps._cells(ref))[0])) == [500, 500]


def test_a_tie_keeps_the_axis_of_the_last_cut():
    """A cube of 8 x 8 x 8 cells filled evenly holds as much cut along any axis: the last cut's
    axis (y) stays."""
    grid = np.stack(np.meshgrid(*(np.arange(8) + 0.5,) * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    steps = RankSteps(TwoRanks(np.zeros(24)), template("particles", cells=(8, 8, 8)))
    steps.axis = 1
    steps._cut(grid)
    assert steps.axis == 1
    assert list(steps.slabs) == [0, 4, 8]
