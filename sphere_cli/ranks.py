"""One scene on several MPI ranks (`mpiexec -n 4 sphere run case.toml`): which rank leads, and the
commands it sends the others.

Rank 0 leads. It builds the scene, writes every file (run directory, logs, trajectory,
checkpoints) and runs the loop of simulation.py, as a one-rank run does; only the steps run split
across the ranks (physics/rank_steps.py). The other ranks follow: they wait for the lead's
commands and end with the lead's exit code. A rank that fails inside the steps aborts every rank
(MPI_Abort); the newest checkpoint, written by the lead between steps, stays intact.

mpi4py is imported only when the launcher started more than one rank.
"""

from __future__ import annotations

import os
import signal
import sys
from contextlib import contextmanager

from .errors import UsageError
from .runtime import MPI_SIZE_VARIABLES, usable_cores

# the exit code of a rank that failed on its own (aborts every rank), and of a stop on request
FAILED = 70
STOPPED = 75


def launched_size() -> int:
    """The rank count the MPI launcher gave this process (1 outside a launcher)."""
    for name in MPI_SIZE_VARIABLES:
        value = os.environ.get(name, "")
        if value.isdigit() and int(value) > 1:
            return int(value)
    return 1


class World:
    """The ranks of this run: MPI.COMM_WORLD, and the order the lead sends the followers."""

    def __init__(self, mpi):
        self.mpi = mpi
        self.comm = mpi.COMM_WORLD
        self.rank = self.comm.Get_rank()
        self.size = self.comm.Get_size()
        # ranks on this node (they share its cores)
        self.node_size = self.comm.Split_type(mpi.COMM_TYPE_SHARED).Get_size()
        self.steps = None  # the rank steps of the scene (physics/rank_steps.py), once started

    @property
    def leads(self) -> bool:
        return self.rank == 0

    def order(self, *command) -> None:
        """The lead tells every follower what to do next (they wait in `follow`)."""
        self.comm.bcast(command, root=0)

    def pids(self) -> list[int]:
        """Every rank's process id, in rank order (for run.log: a rank to signal or kill)."""
        return self.comm.allgather(os.getpid())

    def abort(self, code: int = FAILED) -> None:
        self.comm.Abort(code)

    def together(self, work):
        """The lead's part of a collective step: should it fail midway, the followers wait in
        a message that will never come, so every rank is aborted with the error's exit code
        (75 for a second Ctrl-C); the newest checkpoint is intact."""
        try:
            return work()
        except BaseException as exc:
            code = STOPPED if isinstance(exc, KeyboardInterrupt) else getattr(exc, "exit_code", FAILED)
            message = f"sphere: error: rank 0, during the steps: {type(exc).__name__}: {exc}"
            print(message, file=sys.stderr, flush=True)
            self.abort(code)
            raise

    def follow(self) -> int:
        """A follower's life: carry out the lead's commands until it ends the run; returns the
        lead's exit code. An exception here cannot be reported to the lead (it may wait in a
        collective step): it is printed and every rank aborted."""
        from .physics.rank_steps import RankSteps

        # SIGTERM (scancel, a time limit) and Ctrl-C reach every rank: the lead checkpoints and
        # ends the run, so the followers must outlive the signal
        signal.signal(signal.SIGTERM, signal.SIG_IGN)
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        signal.signal(signal.SIGUSR1, signal.SIG_IGN)
        try:
            while True:
                command, *args = self.comm.bcast(None, root=0)
                if command == "end":
                    return int(args[0])
                if command == "start":
                    self.steps = RankSteps.following(self, *args)
                else:
                    self.steps.carry_out(command, *args)
        except Exception as exc:
            message = f"sphere: error: rank {self.rank}: {type(exc).__name__}: {exc}"
            print(message, file=sys.stderr, flush=True)
            self.abort(FAILED)
            raise


_world: World | None = None


def current() -> World | None:
    """The ranks of this process's run, or None on one rank."""
    return _world


def count() -> int:
    """The ranks running this process's scene (1 without a launcher)."""
    return 1 if _world is None else _world.size


def start() -> World | None:
    """Join the ranks the launcher started (None when it started one): imports mpi4py, and gives
    each rank its share of the node's cores unless the threads are set (simulation.threads wins
    over this, NUMBA_NUM_THREADS too)."""
    global _world
    size = launched_size()
    if size <= 1:
        return None
    try:
        from mpi4py import MPI
    except ImportError:
        raise UsageError(
            f"started as {size} MPI ranks, but mpi4py is not installed: pip install 'sphere-cli[mpi]' "
            "(on a cluster, build it against the site's MPI: see the user guide, 'Many nodes')"
        ) from None
    _world = World(MPI)
    if "NUMBA_NUM_THREADS" not in os.environ:
        import numba

        numba.set_num_threads(max(1, min(numba.config.NUMBA_NUM_THREADS, usable_cores() // _world.node_size)))
    return _world


@contextmanager
def leading(world: World | None):
    """Around the lead's command: whatever way it ends, the followers are told to end with its
    exit code."""
    if world is None:
        yield
        return
    code = FAILED
    try:
        yield
        code = 0
    except SystemExit as exc:
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        raise
    except BaseException as exc:
        code = getattr(exc, "exit_code", FAILED)
        raise
    finally:
        world.order("end", code)
