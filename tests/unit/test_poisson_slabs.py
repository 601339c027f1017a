"""The Poisson solver split across MPI ranks (physics/fluid/poisson.py PoissonSolver.split, Slabs),
run with the real launcher: the mpich wheel's `mpiexec` (test extra).

On 2, 3 and 4 ranks (sub-communicators of one 4-rank launch) every rank must return one rank's
solution, iteration count and residual, bit for bit: the slabs change who computes a column,
never what is computed, and the sums are exact (kernels/exact_sum.py), so in any order. The
systems cover what the slabs meet: the multigrid levels split down to the coarsest, split only
in part, or not at all (an odd plane count), the diagonal preconditioner, the singular
all-no-flux system (its means), periodic x (the halo wraps around), a right-hand side far from
unit size (rescaled), a non-zero first guess, and more ranks than planes. One rank takes the
diagonal preconditioner's iterations in one compiled call (kernels/fluid/poisson.py
diagonal_cg), split ranks one kernel at a time: the same bits, the two diagonal cases show.
"""

from __future__ import annotations

import os
import pickle
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from sphere_cli.physics.fluid.grid import FluidGrid
from sphere_cli.physics.fluid.poisson import PoissonSolver

MPIEXEC = Path(sys.executable).with_name("mpiexec")
RANKS = 4

SYSTEMS = '''
import numpy as np

from sphere_cli.physics.fluid.grid import FluidGrid
from sphere_cli.physics.fluid.poisson import PoissonSolver

# shape, periodic x and y, bottom, top, preconditioner, c > 0, scale of b
CASES = [
    ((16, 6, 12), (True, True), "dirichlet", "no-flux", "multigrid", False, 1.0),
    ((12, 5, 8), (False, False), "no-flux", "no-flux", "multigrid", False, 1.0),
    ((8, 4, 8), (False, True), "dirichlet", "dirichlet", "multigrid", True, 1e-200),
    ((7, 4, 8), (True, False), "dirichlet", "no-flux", "multigrid", False, 1.0),
    ((10, 3, 6), (False, False), "no-flux", "dirichlet", "jacobi", True, 1.0),
    ((3, 4, 16), (True, True), "dirichlet", "no-flux", "multigrid", False, 1.0),
    ((6, 4, 8), (True, True), "no-flux", "no-flux", "jacobi", False, 1.0),  # singular: mean removed
]


def systems():
    """(solver, arguments of solve) for each case, the same on every process."""
    rng = np.random.default_rng(11)
    for shape, periodic, bottom, top, preconditioner, helmholtz, scale in CASES:
        grid = FluidGrid(np.zeros(3), 1.0 / np.asarray(shape), shape, np.array([*periodic, False]))
        solver = PoissonSolver(grid, bottom, top, "pcg", 1e-11, 400, preconditioner, split_cells=1)
        nx, ny, nz = shape
        b = scale * rng.standard_normal(shape)
        c = rng.uniform(0.5, 2.0, shape) if helmholtz else np.zeros(shape)
        ax = rng.uniform(0.1, 3.0, (nx + 1, ny, nz))
        ay = rng.uniform(0.1, 3.0, (nx, ny + 1, nz))
        az = rng.uniform(0.1, 3.0, (nx, ny, nz + 1))
        if periodic[0]:
            ax[nx] = ax[0]
        if periodic[1]:
            ay[:, ny] = ay[:, 0]
        x = scale * rng.standard_normal(shape)
        yield solver, (x, b, c, ax, ay, az, 0.3 * scale, -0.7 * scale)
'''

SCRIPT = (
    SYSTEMS
    + """
import sys

from mpi4py import MPI

world = MPI.COMM_WORLD
out = {}
for ranks in (2, 3, 4):
    comm = world.Split(0 if world.rank < ranks else MPI.UNDEFINED, world.rank)
    for number, (solver, arguments) in enumerate(systems()):
        if comm == MPI.COMM_NULL:
            continue
        solver.split(comm)
        result = solver.solve(*arguments)
        every = comm.gather(arguments[0], root=0)
        if comm.rank == 0:
            for rank, x in enumerate(every):
                out[f"x_{ranks}_{number}_{rank}"] = x
            out[f"result_{ranks}_{number}"] = [result.iterations, result.residual, result.mean_removed]
if world.rank == 0:
    np.savez(sys.argv[1], **out)
"""
)


class Fake:
    """The few calls of a communicator that PoissonSolver.split makes, for rank `rank` of `size`
    (it sends nothing until a solve)."""

    def __init__(self, rank, size):
        self.rank, self.size = rank, size

    def Get_size(self):
        return self.size

    def Get_rank(self):
        return self.rank


pytestmark = pytest.mark.skipif(
    not MPIEXEC.is_file() or shutil.which("mpiexec", path=str(MPIEXEC.parent)) is None,
    reason="no mpiexec beside this Python (the test extra installs the mpich wheel on Linux)",
)


def test_the_solver_split_across_ranks_is_one_ranks_bit_for_bit(tmp_path):
    (tmp_path / "split.py").write_text(SCRIPT)
    env = {
        **os.environ,
        "OMP_WAIT_POLICY": "PASSIVE",
        "NUMBA_NUM_THREADS": "1",
        "MPIR_CVAR_CH4_PROGRESS_THROTTLE": "1",
        "MPIR_CVAR_CH4_PROGRESS_THROTTLE_NO_PROGRESS_COUNT": "100",
    }
    command = [str(MPIEXEC), "-n", str(RANKS), sys.executable, "split.py", "split.npz"]
    run = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=300, env=env)
    assert run.returncode == 0, run.stdout + run.stderr
    split = np.load(tmp_path / "split.npz")
    namespace: dict = {}
    exec(SYSTEMS, namespace)
    for number, (solver, arguments) in enumerate(namespace["systems"]()):
        result = solver.solve(*arguments)
        assert result.converged, (number, result)
        one = np.array([result.iterations, result.residual, result.mean_removed])
        for ranks in (2, 3, 4):
            assert np.array_equal(split[f"result_{ranks}_{number}"], one), (ranks, number)
            for rank in range(ranks):
                x = split[f"x_{ranks}_{number}_{rank}"]
                assert np.array_equal(x, arguments[0]), (ranks, number, rank)


def test_the_slabs_split_the_multigrid_levels_the_planes_allow():
    """With no least cell count: 16 planes on 2 ranks, slabs of 8, the level of 8 planes split
    in 4 and 4 and the coarsest whole; on 3 ranks, slabs of whole pairs, 4, 6 and 6; 7 planes on
    2 ranks, 3 and 4 (its only level, the coarsest, whole). With the default least cell count a
    16 x 16 x 32 grid is split on 2 ranks, its first level (1 024 cells) whole, and not at all on
    4. Without a communicator everything is one slab."""
    namespace: dict = {}
    exec(SYSTEMS, namespace)
    solvers = [solver for solver, _ in namespace["systems"]()]

    periodic16, _, _, odd, _, narrow = solvers[:6]
    assert (periodic16.slabs.lo, periodic16.slabs.hi) == (0, 16) and not periodic16.slabs.split
    periodic16.split(Fake(1, 2))
    levels = periodic16.multigrid.levels
    assert [level.shape for level in levels] == [(8, 3, 6), (4, 3, 3)]
    assert [(s.lo, s.hi) for s in [periodic16.slabs] + [level.slabs for level in levels]] == [
        (8, 16),
        (4, 8),
        (0, 4),
    ]
    # periodic x: rank 1's halo planes are 7 and 0, both rank 0's
    assert periodic16.slabs.receive == [(0, 0, 0), (7, 0, 1)]
    assert periodic16.slabs.send == [(15, 0, 1), (8, 0, 0)]
    # two planes deep for the smoothing: 0-1 and 6-7 from rank 0, and the first colour swept
    # on planes 7 to 16 (16: plane 0)
    assert periodic16.slabs.wide and levels[0].slabs.wide
    assert periodic16.slabs.wide_receive == [(0, 0, 2), (6, 0, 3)]
    assert periodic16.slabs.wide_send == [(14, 0, 3), (8, 0, 2)]
    assert periodic16.slabs.extended == (7, 17)
    periodic16.split(Fake(2, 3))  # slabs of 4 planes would give the last 8: pairs, 4, 6 and 6
    assert (periodic16.slabs.lo, periodic16.slabs.hi) == (10, 16)
    assert (levels[0].slabs.lo, levels[0].slabs.hi) == (5, 8) and not levels[1].slabs.split
    assert [s.split for s in [periodic16.slabs] + [level.slabs for level in levels]] == [True, True, False]
    odd.split(Fake(0, 2))
    assert (odd.slabs.lo, odd.slabs.hi) == (0, 3)
    assert [(level.slabs.lo, level.slabs.hi) for level in odd.multigrid.levels] == [(0, 7)]
    narrow.split(Fake(0, 4))  # 3 planes on 4 ranks: the first has none, and no halo
    assert narrow.slabs.lo == narrow.slabs.hi == 0 and not narrow.slabs.receive
    shape = (16, 16, 32)
    grid = FluidGrid(np.zeros(3), 1.0 / np.asarray(shape), shape, np.array([True, True, False]))
    default = PoissonSolver(grid, "dirichlet", "no-flux")
    default.split(Fake(1, 2))
    assert (default.slabs.lo, default.slabs.hi) == (8, 16)
    assert not any(level.slabs.split for level in default.multigrid.levels)
    default = PoissonSolver(grid, "dirichlet", "no-flux")
    default.split(Fake(1, 4))
    assert not default.slabs.split


def test_two_planes_deep_only_where_each_lies_in_one_other_slab():
    """Slabs.wide: every slab two planes or more, and around a periodic axis four or more beyond
    each, so that the two planes either side come from one neighbour each and never overlap."""
    from sphere_cli.physics.fluid.poisson import _two_deep

    assert _two_deep(np.array([0, 4, 8]), True)
    assert not _two_deep(np.array([0, 2, 4]), True)  # both sides' planes 2 and 3
    assert _two_deep(np.array([0, 2, 4]), False)
    assert not _two_deep(np.array([0, 1, 8]), False)  # a slab of one plane
    assert not _two_deep(np.array([0, 8]), True)  # one rank: nothing beside
    grid = FluidGrid(np.zeros(3), 1.0 / np.array([4, 4, 4]), (4, 4, 4), np.array([True, True, False]))
    solver = PoissonSolver(grid, "dirichlet", "no-flux", "pcg", 1e-8, 100, "jacobi", split_cells=1)
    solver.split(Fake(0, 2))
    assert solver.slabs.receive and not solver.slabs.wide and not solver.slabs.wide_receive
    assert solver.slabs.extended == (solver.slabs.lo, solver.slabs.hi)


def test_a_split_solver_sent_to_another_process_arrives_whole():
    """The lead's fluid module is pickled to the other ranks when the scene is shared out again
    (a stage that begins): its solver's slabs must not travel (a communicator does not), and the
    copy solves whole, as one rank does, until that rank splits it."""
    namespace: dict = {}
    exec(SYSTEMS, namespace)
    (solver, arguments), *_ = namespace["systems"]()

    expected = arguments[0].copy()
    solver.solve(expected, *arguments[1:])
    solver.split(Fake(1, 2))
    assert solver.slabs.split and solver.multigrid.levels[0].slabs.split
    copy = pickle.loads(pickle.dumps(solver))
    slabs = [copy.slabs, copy.multigrid.fine_slabs] + [level.slabs for level in copy.multigrid.levels]
    assert not any(s.split for s in slabs)
    assert all((s.lo, s.hi) == (0, s.shape[0]) for s in slabs)
    x = arguments[0].copy()
    copy.solve(x, *arguments[1:])
    assert np.array_equal(x, expected)
