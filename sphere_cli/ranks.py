"""One scene on several MPI ranks (`mpiexec -n 4 sphere run case.toml`): which rank leads, and the
commands it sends the others.

Rank 0 leads. It builds the scene, writes every file (run directory, logs, trajectory,
checkpoints) and runs the loop of simulation.py, as a one-rank run does; only the steps run split
across the ranks (physics/rank_steps.py). The other ranks follow: they wait for the lead's
commands and end with the lead's exit code. A rank that fails inside the steps records its error
in the run's run.log and status.json and aborts every rank (MPI_Abort); the newest checkpoint,
written by the lead between steps, stays intact.

mpi4py is imported only when the launcher started more than one rank.
"""

from __future__ import annotations

import logging
import os
import pickle
import signal
import sys
import time
from contextlib import contextmanager

import numpy as np

from .errors import SphereError, UsageError
from .runtime import launched_size, usable_cores

# the exit code of a rank that failed on its own (aborts every rank), and of a stop on request
FAILED = 70
STOPPED = 75
# a follower looks for the lead's next command without pause for WAIT_SPIN, then sleeps WAIT_SLEEP
# between looks [s]; after a stop signal it waits LEAD_GRACE for the lead before taking it for
# dead [s]
WAIT_SPIN = 0.01
WAIT_SLEEP = 0.0005
LEAD_GRACE = 600.0


class World:
    """The ranks of this run: MPI.COMM_WORLD, and the order the lead sends the followers."""

    def __init__(self, mpi):
        self.mpi = mpi
        self.comm = mpi.COMM_WORLD
        self.rank = self.comm.Get_rank()
        self.size = self.comm.Get_size()
        # ranks on this node (they share its cores)
        self.node_size = self.comm.Split_type(mpi.COMM_TYPE_SHARED).Get_size()
        # the fluid grid's own messages (its solves' halos and sums), apart from the steps'
        self.grid_comm = self.comm.Dup()
        self.steps = None  # the rank steps of the scene (physics/rank_steps.py), once started
        self.run_path: str | None = None  # where a failing rank records its error (record_failures_in)

    @property
    def leads(self) -> bool:
        return self.rank == 0

    def order(self, *command) -> None:
        """The lead tells every follower what to do next (they wait in `follow`)."""
        data = np.frombuffer(pickle.dumps(command), dtype=np.uint8)
        self.comm.Ibcast(np.array([data.size], dtype=np.int64), root=0).Wait()
        self.comm.Bcast(data, root=0)

    def _next_order(self, signalled: list) -> tuple:
        """A follower waits for the lead's next command, sleeping between looks (the lead may
        write files or compile for minutes). After a stop signal the lead checkpoints and ends
        the run; a lead that says nothing for LEAD_GRACE seconds after one has died (a launcher
        that does not end the other ranks then: srun without --kill-on-bad-exit)."""
        size = np.zeros(1, dtype=np.int64)
        request = self.comm.Ibcast(size, root=0)  # the command's length, then the command
        waiting = time.monotonic()
        while True:
            if request.Test():
                data = np.empty(int(size[0]), dtype=np.uint8)
                self.comm.Bcast(data, root=0)
                return pickle.loads(data.tobytes())
            if signalled and time.monotonic() - signalled[-1] > LEAD_GRACE:
                self._fail(
                    f"sphere: error: rank {self.rank}: no word from rank 0 for {LEAD_GRACE:.0f} s after a "
                    "stop signal; it has died. Its newest checkpoint is intact: resume the run.",
                    STOPPED,
                )
            if time.monotonic() - waiting > WAIT_SPIN:  # between steps a command follows at once
                time.sleep(WAIT_SLEEP)

    def pids(self) -> list[int]:
        """Every rank's process id, in rank order (for run.log: a rank to signal or kill)."""
        return self.comm.allgather(os.getpid())

    def abort(self, code: int = FAILED) -> None:
        """End every rank with `code`. MPI_Abort asks the launcher to end them and may return
        before this process is ended: it exits at once, or the exception being reported would
        go on to the run loop's handlers and report itself a second time."""
        self.comm.Abort(code)
        os._exit(code)

    def record_failures_in(self, run_path) -> None:
        """The lead's run directory, told to every rank: a rank that fails alone records its error
        there (run.log, status.json) before it aborts them all, as a one-rank run would."""
        self.run_path = str(run_path)
        if self.leads:
            self.order("record_in", self.run_path)

    def _fail(
        self, message: str, code: int, recorded: str | None = None, progress: dict | None = None
    ) -> None:
        """Report an error that no other rank can hear (they wait in a message), then abort every
        rank with `code`: `message` on stderr, `recorded` (the message unless given) in run.log
        and status.json, with `progress` (step, time) where known."""
        print(message, file=sys.stderr, flush=True)
        if self.run_path is not None:
            from .io.rundir import RunDirectory

            state = "interrupted" if code == STOPPED else "failed"
            RunDirectory(self.run_path).record_abort(recorded or message, state, code, progress)
        self.abort(code)

    def together(self, work, progress=None):
        """The lead's part of a collective step: should it fail midway, the followers wait in
        a message that will never come, so every rank is aborted with the error's exit code
        (75 for a second Ctrl-C); the newest checkpoint is intact. An error of the case or the
        physics (a SphereError, met by every rank alike) is reported as one rank reports it,
        with the step and time progress() gives; anything else names the rank and its type."""
        try:
            return work()
        except BaseException as exc:
            code = STOPPED if isinstance(exc, KeyboardInterrupt) else getattr(exc, "exit_code", FAILED)
            if isinstance(exc, SphereError):
                self._fail(f"sphere: error: {exc}", code, str(exc), progress() if progress else None)
            else:
                self._fail(f"sphere: error: rank 0, during the steps: {type(exc).__name__}: {exc}", code)
            raise

    def follow(self) -> int:
        """A follower's life: carry out the lead's commands until it ends the run; returns the
        lead's exit code. An exception here cannot be reported to the lead (it may wait in a
        collective step): it is printed and every rank aborted."""
        from .physics.rank_steps import RankSteps

        # SIGTERM (scancel, a time limit) and Ctrl-C reach every rank: the lead checkpoints and
        # ends the run, so the followers outlive the signal, noting when it came
        signalled: list[float] = []
        # the lead logs the run (run.log, the launcher's stderr); the fluid steps every rank
        # takes alike (a fluid's step_on_rank) would log their warnings once a rank there
        logging.getLogger("sphere").addHandler(logging.NullHandler())
        for number in (signal.SIGTERM, signal.SIGINT, signal.SIGUSR1):
            signal.signal(number, lambda *_: signalled.append(time.monotonic()))
        try:
            while True:
                command, *args = self._next_order(signalled)
                if command == "end":
                    return int(args[0])
                if command == "record_in":
                    self.run_path = args[0]
                elif command == "start":
                    self.steps = RankSteps.following(self, *args)
                else:
                    self.steps.carry_out(command, *args)
        except Exception as exc:
            self._fail(f"sphere: error: rank {self.rank}: {type(exc).__name__}: {exc}", FAILED)
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
            "(on a cluster, build it against the site's MPI: user guide, section 7)"
        ) from None
    except Exception as exc:  # an MPI library that cannot start
        raise UsageError(f"started as {size} MPI ranks, but MPI did not start: {exc}") from None
    world = World(MPI)
    if world.size != size:
        raise UsageError(
            f"the launcher started {size} ranks but MPI sees {world.size}: mpi4py loads another MPI "
            "than the launcher's (use the mpiexec of the MPI mpi4py was built with)"
        )
    _world = world
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
