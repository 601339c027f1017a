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


def slabs(balance: str, other: np.ndarray) -> tuple[np.ndarray, float]:
    """The slabs rank 0 cuts for 10 cells when it sends 100 particles in each of cells 0-4,
    holding 600 with its ghosts and having spent 0.6 s in its forces; and its timer after."""
    steps = RankSteps(TwoRanks(other), SimpleNamespace(cells=10, periodic=False, balance=balance))
    steps.part = SimpleNamespace(gid=np.arange(600))
    steps.busy = 0.6
    steps._cut(np.repeat(np.arange(5), 100))
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
