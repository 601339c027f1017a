"""The MPI functions called from compiled code (physics/rank_calls.py, kernels/rank_messages.py),
on two ranks started by the mpich wheel's mpiexec: the reduction and the ghosts' message give
what MPI should, the moving walls' totals summed over both ranks are one rank's bit for bit,
and a second launch loads the compiled functions from Numba's cache instead of
compiling them again (what numba-mpi's calls could not do)."""

from __future__ import annotations

import ctypes.util
import json
import os
import shutil
import subprocess
import sys
import types
from pathlib import Path

import pytest

MPIEXEC = Path(sys.executable).with_name("mpiexec")
pytestmark = pytest.mark.skipif(
    not MPIEXEC.is_file() or shutil.which("mpiexec", path=str(MPIEXEC.parent)) is None,
    reason="no mpiexec beside this Python (the test extra installs the mpich wheel on Linux)",
)

SCRIPT = """\
import json
import time
import types

import numpy as np
from mpi4py import MPI

from sphere_cli.kernels.exact_sum import WORDS
from sphere_cli.kernels.rank_messages import (
    largest_everywhere, own_wall_sums, rank_wall_totals, seconds, send_ghost_forces,
)
from sphere_cli.kernels.walls import finish_wall_totals, wall_totals
from sphere_cli.physics.rank_calls import compiled_calls, ghost_mail

comm = MPI.COMM_WORLD
rank, other = comm.rank, 1 - comm.rank
world = types.SimpleNamespace(mpi=MPI, comm=comm)
mpi, request_type = compiled_calls(MPI, comm)

mine, largest = np.array([10.0 + rank]), np.zeros(1)
code = largest_everywhere(mpi, mine, largest)
# on a communicator made by MPI_Comm_dup (a fluid grid's): MPICH sets the top bit of its handle
dup_mpi, _ = compiled_calls(MPI, comm.Dup())
dup_largest = np.zeros(1)
dup_code = largest_everywhere(dup_mpi, np.array([20.0 - rank]), dup_largest)

# 4 particles a rank: rows 1 and 3 are owned and ghosts on the other rank, where they are
# rows 0 and 2; each rank's forces are 100 * rank + row, torques their negatives, and a fluid's
# ghost array of one column ten times the force
force = np.array([[100.0 * rank + i] * 3 for i in range(4)])
torque = -force
extra = 10.0 * force[:, :1]
mail = ghost_mail(world, {other: np.array([1, 3])}, {other: np.array([0, 2])}, request_type, width=7)
sent = send_ghost_forces(force, torque, extra, mpi, mail)

# the monotonic clock the loop times its forces by (rank_balance = "time"), over a 50 ms sleep
clock = np.zeros(2, dtype=np.int64)
before, started = seconds(mpi, clock), time.perf_counter()
time.sleep(0.05)
slept, elapsed = seconds(mpi, clock) - before, time.perf_counter() - started

# the walls' totals: 300 particles, half of them pushing walls 0 and 2 (recorded) and 1 (not),
# with forces from 1e-8 to 1e8 (the order of a float sum shows in its bits), and 20 glued spheres
# (forces as spread); each rank owns blocks of 7 particles in turn and adds its share to the
# other's: one rank's totals
rng = np.random.default_rng(7)
n, walls = 300, 3
pforce = np.zeros((n, walls, 3))
pushing = rng.random(n) < 0.5
shape = (pushing.sum(), walls, 3)
pforce[pushing] = rng.standard_normal(shape) * 10.0 ** rng.integers(-8, 9, shape)
record = np.array([1, 0, 1], dtype=np.uint8)
totals_of, mass = rng.standard_normal((n, 3)) * 10.0 ** rng.integers(-8, 9, (n, 3)), rng.random(n)
attached, attached_wall = rng.permutation(n)[:20], rng.integers(0, walls, 20)
body_acc, fluid_force = np.array([0.0, 0.0, -9.81]), rng.standard_normal((walls, 3))
one, split = np.zeros((walls, 3)), np.zeros((walls, 3))
words = lambda: np.zeros((walls, 3, WORDS), dtype=np.int64)
wall_totals(pforce, record, words(), attached, attached_wall, totals_of, mass, body_acc, fluid_force, one)
gid = np.arange(n)
own = gid[(gid // 7) % 2 == rank]
glued = attached[(attached // 7) % 2 == rank]
glued_wall = attached_wall[(attached // 7) % 2 == rank]
share = (own, pforce, record, glued, glued_wall, totals_of, mass, body_acc)
totals = rank_wall_totals(mpi, *share, words(), words(), fluid_force, split)
# again with rank 1 adding its share from Python (summed_over_ranks, as a rank stepping with the
# energy budget or holding no particle does) while rank 0 takes it in compiled code: the same
# message
mixed = np.zeros((walls, 3))
if rank == 0:
    rank_wall_totals(mpi, *share, words(), words(), fluid_force, mixed)
else:
    from sphere_cli.physics.rank_steps import summed_over_ranks

    sums = words()
    own_wall_sums(*share, sums)
    finish_wall_totals(summed_over_ranks(world, sums), record, fluid_force, mixed)

KERNELS = (largest_everywhere, send_ghost_forces, seconds, rank_wall_totals)
open(f"rank{rank}.json", "w").write(json.dumps({
    "rank": rank, "code": int(code), "largest": float(largest[0]), "sent": int(sent),
    "dup_code": int(dup_code), "dup_largest": float(dup_largest[0]),
    "force": force[:, 0].tolist(), "torque": torque[:, 2].tolist(), "extra": extra[:, 0].tolist(),
    "slept": slept, "elapsed": elapsed,
    "totals": int(totals), "one": one.tolist(), "split": split.tolist(), "fluid": fluid_force.tolist(),
    "mixed": mixed.tolist(),
    "compiled": sum(sum(f.stats.cache_misses.values()) for f in KERNELS),
    "loaded": sum(sum(f.stats.cache_hits.values()) for f in KERNELS),
}))
"""


KERNEL_NAMES = ("largest_everywhere", "send_ghost_forces", "seconds", "rank_wall_totals")  # the script's


def launch(tmp_path: Path) -> list[dict]:
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "NUMBA_NUM_THREADS": "1"}
    result = subprocess.run(
        [str(MPIEXEC), "-n", "2", sys.executable, str(tmp_path / "script.py")],
        capture_output=True, text=True, timeout=300, env=env, cwd=tmp_path,
    )  # fmt: skip
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Warning" not in result.stderr, result.stderr
    return [json.loads((tmp_path / f"rank{rank}.json").read_text()) for rank in (0, 1)]


def test_compiled_messages_reach_the_other_rank_and_are_cached(tmp_path):
    (tmp_path / "script.py").write_text(SCRIPT)
    first = launch(tmp_path)
    for r in first:
        assert r["code"] == 0 and r["sent"] == 0
        assert r["largest"] == 11.0  # the larger of 10 and 11, on both ranks
        assert r["dup_code"] == 0 and r["dup_largest"] == 20.0
        theirs = 100.0 * (1 - r["rank"])
        mine = 100.0 * r["rank"]
        # rows 0 and 2 now hold the owner's rows 1 and 3; rows 1 and 3 are untouched
        assert r["force"] == [theirs + 1, mine + 1, theirs + 3, mine + 3]
        assert r["torque"] == [-(theirs + 1), -(mine + 1), -(theirs + 3), -(mine + 3)]
        assert r["extra"] == [10 * (theirs + 1), 10 * (mine + 1), 10 * (theirs + 3), 10 * (mine + 3)]
        # each kernel compiled by one rank or both (the other may find it in the shared cache)
        assert r["compiled"] + r["loaded"] == len(KERNEL_NAMES)
        assert 0.05 <= r["slept"] <= r["elapsed"] + 1e-3  # the clocks agree to a millisecond
        assert r["totals"] == 0
        assert r["split"] == r["one"]  # bitwise: the floats' repr is exact
        assert r["one"][1] == r["fluid"][1] and r["one"][0] != r["fluid"][0]  # wall 1 not recorded
    # rank 0's compiled reduction met rank 1's from Python: one rank's totals on both
    for r in first:
        assert r["mixed"] == r["one"]
    assert sum(r["compiled"] for r in first) >= len(KERNEL_NAMES)
    again = launch(tmp_path)
    for r in again:
        assert r["compiled"] == 0 and r["loaded"] == len(KERNEL_NAMES)


def test_an_mpi_whose_functions_cannot_be_found_leaves_the_steps_to_python(tmp_path):
    """An mpi4py module through whose library MPI_Allreduce & co. cannot be found (one loading its
    MPI privately, or none at that path): no compiled calls, so the ranks step from Python."""
    from sphere_cli.physics.rank_calls import compiled_calls

    libc = ctypes.util.find_library("c")
    assert libc is not None
    for library in (libc, str(tmp_path / "missing.so")):
        world = types.SimpleNamespace(mpi=types.SimpleNamespace(__file__=library), comm=None)
        assert compiled_calls(world.mpi, world.comm) is None
