"""What a run needs of the process it runs in: its threads, the signals that ask it to stop, the
wall-time budget, a warning when its OpenMP threads would share their cores with other busy
processes, and the sizes of the processor's caches (the pair sweep's choice, the benchmarks'
record).

Numba's OpenMP threads spin while they wait for each other. On cores of their own that is the
fastest way to wait; when another busy process holds one of those cores, every parallel region
waits for a thread that is not running, and a run on 2 threads measured 25-30 x slower than on
one (docs/performance.md). OMP_WAIT_POLICY=PASSIVE makes the threads sleep instead, which costs a
wake-up at every parallel region when the cores are free (small scenes 4-7 x slower). So a run
whose threads would share their cores, and whose user has not chosen a policy, is given the
passive one before its threads start; a chosen policy is kept, with a warning."""

from __future__ import annotations

import functools
import os
import re
import signal
import sys
import time
from contextlib import contextmanager

from .errors import UsageError

# what MPI launchers tell each process of the number of ranks (Open MPI, MPICH/Intel MPI's PMI,
# MVAPICH); SLURM's own variables are not read: a batch script's SLURM_NTASKS describes the
# allocation, not how many copies of this process were started
MPI_SIZE_VARIABLES = ("OMPI_COMM_WORLD_SIZE", "PMI_SIZE", "MV2_COMM_WORLD_SIZE")

# how long the other processes' use of the cores is sampled [s]; /proc/stat counts in 1/100 s
SAMPLE_SECONDS = 0.1
# a busy process sharing our cores holds most of one; half of one is the margin for noise
MARGIN_CORES = 0.5
# the largest cache assumed where the system does not describe it [bytes]: that of the machines
# this project is timed on (docs/performance.md)
DEFAULT_CACHE_BYTES = 32 * 1024**2


def busy_cores(stat_before: str, stat_after: str) -> float:
    """Cores kept busy between two readings of /proc/stat (user, nice, system, irq and softirq
    time; idle, iowait and a hypervisor's steal are not busy here), from its first line."""
    before = [int(v) for v in stat_before.split("\n", 1)[0].split()[1:]]
    after = [int(v) for v in stat_after.split("\n", 1)[0].split()[1:]]
    delta = [a - b for a, b in zip(after, before, strict=False)]
    total = sum(delta[:8])  # user nice system idle iowait irq softirq steal (guest is in user)
    if total <= 0:
        return 0.0
    busy = delta[0] + delta[1] + delta[2] + delta[5] + delta[6]
    cores = os.cpu_count() or 1
    return cores * busy / total


def usable_cores() -> int:
    """The cores this process may run on (a batch job's or container's CPU set), else all."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not Linux
        return os.cpu_count() or 1


def cache_sizes(cpu: str = "/sys/devices/system/cpu/cpu0/cache") -> dict[str, str]:
    """The first core's data caches by level as Linux describes them ({"L1": "48K", "L2":
    "1024K", "L3": "32768K"}: `cpu` holds one index folder per cache, with its type, level and
    size); empty elsewhere."""
    sizes = {}
    try:
        folders = sorted(os.scandir(cpu), key=lambda folder: folder.name)
    except OSError:
        return sizes
    for folder in folders:
        if not folder.name.startswith("index"):
            continue
        try:
            with open(os.path.join(folder.path, "type")) as kind:
                if kind.read().strip() == "Instruction":
                    continue
            with open(os.path.join(folder.path, "level")) as level:
                with open(os.path.join(folder.path, "size")) as size:
                    sizes[f"L{level.read().strip()}"] = size.read().strip()
        except OSError:
            continue
    return sizes


@functools.lru_cache(maxsize=4)  # read once: the pair forces ask at every step
def last_level_cache_bytes(cpu: str = "/sys/devices/system/cpu/cpu0/cache") -> int:
    """Bytes of the processor's largest cache (cache_sizes: its highest level), or
    DEFAULT_CACHE_BYTES where that cannot be read (another system, a container without it)."""
    sizes = cache_sizes(cpu)
    if not sizes:
        return DEFAULT_CACHE_BYTES
    size = re.fullmatch(r"(\d+)([KMG]?)", sizes[max(sizes, key=lambda name: int(name[1:]))])
    if size is None:
        return DEFAULT_CACHE_BYTES
    return int(size[1]) * 1024 ** " KMG".index(size[2] or " ")


def measure_busy_cores(seconds: float = SAMPLE_SECONDS, stat: str = "/proc/stat") -> float | None:
    """Cores that other processes keep busy now (this one sleeps while it samples); None where
    /proc/stat cannot be read (not Linux)."""
    try:
        with open(stat, encoding="ascii") as f:
            before = f.read()
        time.sleep(seconds)
        with open(stat, encoding="ascii") as f:
            after = f.read()
    except OSError:
        return None
    return busy_cores(before, after)


def shared_cores(
    threads: int,
    cores: int | None = None,
    busy: float | None = None,
    wait_policy: str | None = None,
    layer: str | None = None,
) -> tuple[float, int] | None:
    """(cores other processes keep busy, this machine's cores) when those leave fewer free cores
    than the `threads` spinning threads of a run, else None. The arguments after `threads`
    default to this machine's: its core count, the busy cores now (measured only when needed),
    OMP_WAIT_POLICY and NUMBA_THREADING_LAYER."""
    if threads < 2:
        return None
    if waits_passively(wait_policy, layer):
        return None
    if cores is None:
        cores = os.cpu_count() or 1
    if busy is None:
        busy = measure_busy_cores()
        if busy is None:
            return None
    if threads <= cores - busy + MARGIN_CORES:
        return None
    return busy, cores


def _fewer_free_cores(busy: float, cores: int, threads: int) -> str:
    return (
        f"other processes keep {busy:.1f} of this machine's {cores} cores busy, which leaves fewer "
        f"than the {threads} threads of this run"
    )


def shared_cores_note(threads: int, **machine) -> str | None:
    """The warning to give before a run on `threads` spinning threads that would share their
    cores (shared_cores, which takes `machine`), or None."""
    shared = shared_cores(threads, **machine)
    if shared is None:
        return None
    return (
        f"{_fewer_free_cores(*shared, threads)}; OpenMP threads spin while they wait, so sharing "
        "cores can slow the run many times over: set OMP_WAIT_POLICY=PASSIVE, or fewer threads "
        "(simulation.threads, NUMBA_NUM_THREADS)"
    )


class StopFlag:
    """Set from a signal handler or the wall-time budget; read between bursts of steps (about
    0.05 s of wall time, simulation.Loop)."""

    def __init__(self):
        self.reason: str | None = None
        # a second SIGINT: stop at once, with no final checkpoint (its KeyboardInterrupt is
        # raised where it lands, and raised again at the next step if Python dropped it there)
        self.interrupted = False

    def request(self, reason: str) -> None:
        if self.reason is None:
            self.reason = reason


def refuse_many_ranks(joined: bool) -> None:
    """A run that an MPI launcher started as several ranks without their joining into one scene
    (a library call or a sweep member under mpiexec -n 4; the `sphere run` and `sphere resume`
    commands join them: sphere_cli/ranks.py) would be that many copies of one scene racing for
    one run directory: refused before anything is written."""
    launcher = _launcher_ranks()
    if launcher is not None and not joined:
        name, value = launcher
        raise UsageError(
            f"started as {value} MPI ranks ({name}={value}) outside `sphere run` / `sphere resume`: "
            "each rank would run the whole scene into one run directory. Split one scene across "
            "ranks with `mpiexec -n N sphere run CASE`; run independent cases with `sphere sweep`; "
            "or start one process"
        )


# Without `simulation.threads`, each part of a step gets a thread for so much of its work: the
# particles' kernels one for each PARTICLES_PER_THREAD particles, a fluid grid's own step one
# for each CELLS_PER_THREAD cells. Each parallel region costs about 3 us to start on two
# spinning threads against none for the serial twins one thread runs (kernels/serial.py), about
# 18 us a DEM step: two threads overtook one at about 700 particles of a settled bed, 3 000-10 000
# of a loose one, and on a Navier-Stokes grid at about 1 000 cells. Threads that sleep between
# regions (OMP_WAIT_POLICY=PASSIVE; the workqueue and TBB layers) are woken at each, about
# 45 us a region under OpenMP on the 2-core test machine: there two threads overtook one at
# about 8 000 particles and 40 000 cells, and a Darcy grid of 192 cells stepped 14 x slower on
# two (docs/performance.md, 2026-12-05 night)
PARTICLES_PER_THREAD = 500
CELLS_PER_THREAD = 2048
PASSIVE_PARTICLES_PER_THREAD = 8000
PASSIVE_CELLS_PER_THREAD = 32768


def _launcher_ranks() -> tuple[str, str] | None:
    """(the launcher's variable, its value: the rank count) where an MPI launcher started this
    process as one of several ranks, else None."""
    for name in MPI_SIZE_VARIABLES:
        value = os.environ.get(name, "")
        if value.isdigit() and int(value) > 1:
            return name, value
    return None


def launched_size() -> int:
    """The rank count the MPI launcher gave this process (1 outside a launcher)."""
    launcher = _launcher_ranks()
    return 1 if launcher is None else int(launcher[1])


def waits_passively(policy: str | None = None, layer: str | None = None) -> bool:
    """Whether the threads sleep between parallel regions, so that each region pays for waking
    them: OpenMP's under OMP_WAIT_POLICY=PASSIVE (the user's or start_threads'), and those of
    Numba's workqueue and TBB layers, which do not spin (TBB yields after a short spin; two
    workqueue threads stepped 1 000 spheres at 2.3 M particle-steps/s against one thread's 14.8 M).
    `policy` and `layer` instead of OMP_WAIT_POLICY and NUMBA_THREADING_LAYER."""
    if policy is None:
        policy = os.environ.get("OMP_WAIT_POLICY", "")
    if layer is None:
        layer = os.environ.get("NUMBA_THREADING_LAYER", "default")
    return policy.strip().lower() == "passive" or layer.strip().lower() in ("workqueue", "tbb")


def run_threads(case, count: int | None = None) -> int:
    """The run's thread count, never more than NUMBA_NUM_THREADS allows (read from Numba's
    configuration: asking Numba itself would start its threads): `simulation.threads`; else
    one per PARTICLES_PER_THREAD particles (PASSIVE_PARTICLES_PER_THREAD where the threads wait
    passively), at least one, of `count` particles, or the case's particles.count; else (particles
    placed from a file the caller did not count) all of them. A fluid grid's own step takes its
    own count (grid_threads)."""
    import numba

    allowed = numba.config.NUMBA_NUM_THREADS
    if case.simulation.threads is not None:
        return min(case.simulation.threads, allowed)
    if count is None:
        count = case.particles.count
    if count is None:
        return allowed
    return _share(count, PARTICLES_PER_THREAD, PASSIVE_PARTICLES_PER_THREAD, allowed)


def grid_threads(case, cells: int) -> int | None:
    """The thread count of a fluid grid's own step (physics/fluid_plugin.py), once the run's are
    set: None (the run's) where `simulation.threads` is set; else one per CELLS_PER_THREAD of its
    cells (PASSIVE_CELLS_PER_THREAD where the threads wait passively), at least one, at most
    NUMBA_NUM_THREADS, or on MPI ranks the rank's share (sphere_cli/ranks.py)."""
    import numba

    if case.simulation.threads is not None:
        return None
    allowed = numba.get_num_threads() if launched_size() > 1 else numba.config.NUMBA_NUM_THREADS
    return _share(cells, CELLS_PER_THREAD, PASSIVE_CELLS_PER_THREAD, allowed)


def _share(work: int, spinning: int, sleeping: int, allowed: int) -> int:
    """One thread for each `spinning` items of work (`sleeping` where the threads wait
    passively), at least one, at most `allowed`."""
    return max(1, min(allowed, work // (sleeping if waits_passively() else spinning)))


@contextmanager
def threads_set_to(count: int | None):
    """Parallel kernels inside run on `count` threads (None: as they are), then as before."""
    import numba

    before = numba.get_num_threads()
    if count is None or count == before:
        yield
        return
    numba.set_num_threads(count)
    try:
        yield
    finally:
        numba.set_num_threads(before)


def set_threads(case, count: int | None = None) -> None:
    """The run's Numba threads (run_threads); on MPI ranks without `simulation.threads`, those
    sphere_cli/ranks.py gave each rank (the node's cores shared between its ranks) instead."""
    import numba

    if case.simulation.threads is None and launched_size() > 1:
        return
    numba.set_num_threads(run_threads(case, count))


@contextmanager
def threads_restored():
    """Around a run in a process that goes on after it (a notebook, a test): the Numba thread
    count the process had, given back when the run ends (the run sets its own: set_threads)."""
    import numba

    before = numba.get_num_threads() if threads_started() else numba.config.NUMBA_NUM_THREADS
    try:
        yield
    finally:
        if threads_started():
            numba.set_num_threads(before)


def threads_started() -> bool:
    """True once Numba's threading layer runs in this process (any thread count asked or set
    starts it): OpenMP has then read OMP_WAIT_POLICY, and setting it changes nothing."""
    import numba

    try:
        numba.threading_layer()
    except ValueError:  # "not initialized"
        return False
    return True


def start_threads(case, count: int | None = None) -> str | None:
    """The run's threads, with a wait policy for the cores they get. Where other busy processes
    share those cores (shared_cores), OMP_WAIT_POLICY is unset and the threads have not
    started in this process, the threads are made to wait passively (a note on stderr); where
    the policy is the user's, or too late to set, a warning says what to do. Returns that line
    for the run's log. Called once the command is known to go ahead and before any kernel runs,
    so that no thread of this run counts as busy. `count`: the particles, where the case does not
    say (run_threads)."""
    import numba

    chosen = os.environ.get("OMP_WAIT_POLICY", "").strip()
    if not chosen and not threads_started():
        threads = run_threads(case, count)
        shared = shared_cores(threads)
        note = None
        if shared is not None:
            os.environ["OMP_WAIT_POLICY"] = "PASSIVE"  # read by OpenMP when it starts, below
            note = (
                f"{_fewer_free_cores(*shared, threads)}: its threads wait passively "
                "(OMP_WAIT_POLICY=PASSIVE) instead of spinning; OMP_WAIT_POLICY=ACTIVE keeps them spinning"
            )
            print(f"sphere: note: {note}", file=sys.stderr)
        set_threads(case, count)
        return note
    set_threads(case, count)
    note = shared_cores_note(numba.get_num_threads())
    if note is not None:
        print(f"sphere: warning: {note}", file=sys.stderr)
    return note


@contextmanager
def signal_handlers(stop: StopFlag, enabled: bool):
    """SIGTERM/SIGUSR1 (what SLURM sends before a time limit), SIGHUP (the terminal the run was
    started from has closed; its default would end the run without a checkpoint, and what it
    prints now goes nowhere, io/console.py) and a first SIGINT ask for a checkpoint at the next
    step; a second SIGINT stops at once (KeyboardInterrupt). A signal the run was started
    ignoring stays ignored: SIGHUP under nohup, whose user wants the run to outlive the
    terminal, and SIGINT in a background job of a non-interactive shell, as Python keeps it."""
    if not enabled:
        yield
        return

    def polite(signum, _frame):
        name = signal.Signals(signum).name
        if signum == signal.SIGINT and stop.reason is not None:
            stop.interrupted = True
            raise KeyboardInterrupt
        stop.request(f"{name} received")

    def drop_interrupt(unraisable):
        # a KeyboardInterrupt raised inside a finalizer or weakref callback (h5py's, say) is
        # dropped there by Python with a traceback; the loop raises it again at the next step
        if not issubclass(unraisable.exc_type, KeyboardInterrupt):
            previous_hook(unraisable)

    asking = (signal.SIGTERM, signal.SIGUSR1, signal.SIGHUP, signal.SIGINT)
    previous = {s: signal.signal(s, polite) for s in asking if signal.getsignal(s) != signal.SIG_IGN}
    previous_hook, sys.unraisablehook = sys.unraisablehook, drop_interrupt
    try:
        yield
    finally:
        sys.unraisablehook = previous_hook
        for s, handler in previous.items():
            signal.signal(s, handler)


SECONDS = re.compile(r"\d+(?:\.\d*)?")
# SLURM's time forms (sbatch --time): MM:SS, HH:MM:SS, D-HH, D-HH:MM, D-HH:MM:SS
CLOCK = re.compile(
    r"(?:(?P<days>\d+)-(?P<dh>\d+)(?::(?P<dm>\d+))?(?::(?P<ds>\d+))?|(?P<a>\d+):(?P<b>\d+)(?::(?P<c>\d+))?)"
)
# a sum of numbers with units: 90s, 45m, 2h30m, 1d12h, 1.5h
COMPOUND = re.compile(r"(?:\d+(?:\.\d*)?[smhd])+")
UNIT_SECONDS = {"s": 1.0, "m": 60.0, "h": 3600.0, "d": 86400.0}


def parse_wall_time(text: str | None) -> float | None:
    """'3600' (seconds), '45m', '2h30m', '1.5d', or SLURM's '30:00', '2:30:00', '1-12:00:00' ->
    seconds."""
    if text is None:
        return None
    s = text.strip().lower().replace(" ", "")
    seconds = None
    if SECONDS.fullmatch(s):
        seconds = float(s)
    elif match := CLOCK.fullmatch(s):
        g = {k: int(v) if v is not None else 0 for k, v in match.groupdict().items()}
        if match["days"] is not None:
            seconds = g["days"] * 86400.0 + g["dh"] * 3600.0 + g["dm"] * 60.0 + g["ds"]
        elif match["c"] is not None:  # HH:MM:SS
            seconds = g["a"] * 3600.0 + g["b"] * 60.0 + g["c"]
        else:  # MM:SS
            seconds = g["a"] * 60.0 + g["b"]
    elif COMPOUND.fullmatch(s):
        seconds = sum(float(n) * UNIT_SECONDS[u] for n, u in re.findall(r"(\d+(?:\.\d*)?)([smhd])", s))
    if seconds is None:
        raise ValueError(
            f"{text!r}: expected a duration: seconds (3600), with units (45m, 2h30m, 1.5d) "
            "or as SLURM writes it (30:00, 2:30:00, 1-12:00:00)"
        )
    return seconds
