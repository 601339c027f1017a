"""`sphere`: the command line. Parses arguments, calls `api`, maps errors to exit codes.

Exit codes (design guide §6): 0 done; 2 usage; 65 bad case file; 66 missing input;
69 optional package missing (plot without matplotlib); 70 numerical failure; 73 run directory
in use by another sphere process; 74 I/O failure; 75 stopped early on request; 78 resume refused.
"""

from __future__ import annotations

import json
import math
import os
import sys
from contextlib import contextmanager
from enum import StrEnum
from pathlib import Path

import typer

from . import api
from .errors import OutputError, SphereError, StoppedEarly, UsageError
from .io.console import guard_console
from .io.json_text import json_text
from .runtime import StopFlag, parse_wall_time, signal_handlers, usable_cores

app = typer.Typer(
    add_completion=True,  # --install-completion / --show-completion for bash, zsh, fish
    no_args_is_help=True,
    pretty_exceptions_enable=False,
    # help texts are plain text: rich markup would take "[s]" or "sphere-cli[plot]" for its tags
    rich_markup_mode=None,
    context_settings={"help_option_names": ["-h", "--help"]},
    help="sphere: discrete-element simulation of dry and fluid-saturated granular materials.",
)


def _wall_time(text: str | None) -> float | None:
    try:
        return parse_wall_time(text)
    except ValueError as exc:
        raise typer.BadParameter(str(exc)) from None


WALL_TIME_HELP = (
    "Checkpoint and exit 75 after this long: 3600 (s), 45m, 2h30m, or SLURM's 2:30:00, 1-00:00:00."
)


def check_end_time(value: float | None) -> float | None:
    """--until: a positive, finite number of seconds."""
    if value is not None and not (math.isfinite(value) and value > 0):
        raise typer.BadParameter(f"{value}: expected a positive end time in seconds")
    return value


def _show_version(value: bool) -> None:
    if value:
        from .io.provenance import provenance

        typer.echo(f"sphere {provenance()['sphere_version']}")
        raise typer.Exit()


@app.callback()
def _main(
    version: bool = typer.Option(
        False, "--version", callback=_show_version, is_eager=True, help="Print the version and exit."
    ),
) -> None:
    """sphere: discrete-element simulation of dry and fluid-saturated granular materials."""


def _fail(exc: SphereError) -> None:
    typer.echo(f"sphere: error: {exc}", err=True)
    raise typer.Exit(exc.exit_code)


@app.command()
def validate(
    case: Path = typer.Argument(..., metavar="CASE", help="Case file (TOML)."),
    as_json: bool = typer.Option(False, "--json", help="Print the resolved case as JSON."),
) -> None:
    """Check a case file without running it; print the resolved case (defaults filled in)."""
    from .config.load import render_toml

    try:
        resolved = api.validate(case)
    except SphereError as exc:
        _fail(exc)
    if as_json:
        typer.echo(json.dumps(resolved, indent=2))
    else:
        typer.echo(f"# {case}: valid. The case as it runs, every default filled in (valid TOML)\n")
        typer.echo(render_toml(resolved), nl=False)


@app.command()
def schema() -> None:
    """Print the JSON schema of case files (for editors)."""
    typer.echo(json.dumps(api.schema(), indent=2))


class Device(StrEnum):
    cpu = "cpu"
    cuda = "cuda"


DEVICE_OPTION = typer.Option(
    None,
    "--device",
    help='Where the steps run, instead of simulation.device: "cpu" or "cuda" (an NVIDIA GPU, needs '
    "pip install 'sphere-cli[cuda]'; agrees with the CPU to round-off).",
)


@contextmanager
def _ranks():
    """Under an MPI launcher, rank 0 runs the command and the other ranks follow it
    (sphere_cli/ranks.py), ending with its exit code; on one rank, nothing."""
    from . import ranks

    try:
        world = ranks.start()
    except SphereError as exc:
        _fail(exc)
    if world is not None and not world.leads:
        raise typer.Exit(world.follow())
    with ranks.leading(world):
        yield


@app.command()
def run(
    case: Path = typer.Argument(..., metavar="CASE", help="Case file (TOML)."),
    output: Path | None = typer.Option(
        None, "-o", "--output", help="Run directory (default runs/<case name>)."
    ),
    overwrite: bool = typer.Option(
        False,
        "--overwrite",
        help="Replace an existing run directory (only one sphere wrote; the old run is kept aside "
        "until the new run's first checkpoint).",
    ),
    until: float | None = typer.Option(
        None, "--until", callback=check_end_time, help="End time [s] instead of simulation.duration."
    ),
    max_wall_time: str | None = typer.Option(
        None,
        "--max-wall-time",
        help=WALL_TIME_HELP,
    ),
    quiet: bool = typer.Option(False, "-q", "--quiet", help="No progress output."),
    device: Device | None = DEVICE_OPTION,
) -> None:
    """Run a case: build the scene, advance it, write trajectory and checkpoints. Under an MPI
    launcher (mpiexec -n 4 sphere run CASE) the scene's steps are split across the ranks."""
    with _ranks():
        try:
            result = api.run(
                case,
                output,
                overwrite=overwrite,
                max_wall_time=_wall_time(max_wall_time),
                handle_signals=True,
                show_progress=not quiet,
                until=until,
                device=None if device is None else device.value,
            )
        except SphereError as exc:
            _fail(exc)
        except KeyboardInterrupt:
            _interrupted()
        _report(result)


@app.command()
def resume(
    run_dir: Path = typer.Argument(..., metavar="RUN_DIR", help="Run directory written by `sphere run`."),
    until: float | None = typer.Option(
        None, "--until", callback=check_end_time, help="New end time [s] (default: the case's duration)."
    ),
    max_wall_time: str | None = typer.Option(
        None,
        "--max-wall-time",
        help=WALL_TIME_HELP,
    ),
    quiet: bool = typer.Option(False, "-q", "--quiet", help="No progress output."),
    device: Device | None = DEVICE_OPTION,
) -> None:
    """Continue a run from its newest checkpoint that verifies (bitwise identical continuation on
    the device it ran on, and on any number of MPI ranks)."""
    with _ranks():
        try:
            result = api.resume(
                run_dir,
                until=until,
                max_wall_time=_wall_time(max_wall_time),
                handle_signals=True,
                show_progress=not quiet,
                device=None if device is None else device.value,
            )
        except SphereError as exc:
            _fail(exc)
        except KeyboardInterrupt:
            _interrupted()
        _report(result)


@app.command()
def inspect(
    path: Path = typer.Argument(..., metavar="PATH", help="Run directory, trajectory.h5 or checkpoint file."),
    as_json: bool = typer.Option(False, "--json", help="Print the summary as JSON."),
) -> None:
    """Summarise any output: case, particles, time reached, energies, checkpoints and their integrity."""
    from .io.inspect import render

    try:
        summary = api.inspect(path)
    except SphereError as exc:
        _fail(exc)
    typer.echo(api.to_json(summary) if as_json else render(summary))


@app.command()
def plot(
    run_dir: Path = typer.Argument(..., metavar="RUN_DIR", help="Run directory (or its trajectory.h5)."),
    output: Path | None = typer.Option(
        None, "-o", "--output", help="Folder for the PNG files (default RUN_DIR/plots)."
    ),
) -> None:
    """Draw the observables as PNG files: time series of stress, friction, dilation, energy and
    structure, and the layer profiles (needs matplotlib: pip install 'sphere-cli[plot]')."""
    try:
        written = api.plot(run_dir, output)
    except SphereError as exc:
        _fail(exc)
    for path in written:
        typer.echo(str(path))


bench_app = typer.Typer(
    no_args_is_help=True,
    rich_markup_mode=None,
    help="Benchmarks (never part of the tests): dem, ranks, gpu, fluid, darcy, vans1d, grid, compile.",
)
app.add_typer(bench_app, name="bench")

THREADS_OPTION = typer.Option("1,2", "--threads", help="Thread counts, comma-separated.")
CELLS_OPTION = typer.Option(64, "--cells", min=4, help="Fluid cells along each axis.")
PARTICLES_OPTION = typer.Option(20_000, "--particles", min=1, help="Particles in the scene.")
COUPLED_STEPS_OPTION = typer.Option(20, "--steps", min=1, help="Coupled steps per timing.")
OUTPUT_OPTION = typer.Option(
    Path("bench-results"),
    "-o",
    "--output",
    help="Folder for the results (the settled beds are cached in the user cache directory).",
)


def _numbers(text: str, option: str = "--threads") -> tuple[int, ...]:
    """Counts (particles, threads, ranks, cells): comma-separated whole numbers of at least 1
    (0 divided by zero in the rates, or ran as one thread or rank under another name)."""
    try:
        counts = tuple(int(x) for x in text.split(",") if x.strip())
    except ValueError:
        raise typer.BadParameter(f"{option} {text!r}: expected comma-separated integers") from None
    if any(count < 1 for count in counts):
        raise typer.BadParameter(f"{option} {text!r}: expected counts of at least 1")
    return counts


def _thread_counts(text: str) -> tuple[int, ...]:
    """--threads: counts of at least 1 and at most what Numba may start here (a larger one was
    skipped without a word by some benchmarks and ended others in a traceback)."""
    import numba

    counts = _numbers(text)
    most = numba.config.NUMBA_NUM_THREADS
    if any(count > most for count in counts):
        raise typer.BadParameter(
            f"--threads {text!r}: at most {most} here (NUMBA_NUM_THREADS, by default the cores this "
            "process may run on)"
        )
    return counts


def _lids(walls: str) -> tuple[str, ...]:
    """The lids of --walls: fixed and/or moving."""
    lids = tuple(s.strip() for s in walls.split(",") if s.strip())
    if not lids or not set(lids) <= {"fixed", "moving"}:
        raise typer.BadParameter(f"--walls {walls!r}: expected fixed and/or moving")
    return lids


def _bench(run, output: Path | None = None) -> None:
    """Run a benchmark; one that writes its results into `output` first makes sure it can (a
    folder that cannot be made or written ended the benchmark in a traceback, after its runs)."""
    try:
        if output is not None:
            _results_folder(output)
        run()
    except SphereError as exc:
        _fail(exc)


def _results_folder(output: Path) -> None:
    """OutputError unless the folder results go to can be written, or made where it is missing
    (nothing is made here: a command refused for another reason leaves no folder behind)."""
    existing = output
    while not existing.exists() and existing.parent != existing:
        existing = existing.parent
    if not existing.is_dir():
        why = f"{existing} is not a folder"
    elif not os.access(existing, os.W_OK | os.X_OK):
        why = f"{existing} cannot be written"
    else:
        return
    raise OutputError(f"{output}: cannot write the results there ({why})")


@bench_app.command("dem")
def bench_dem(
    sizes: str = typer.Option("10000,100000", "--sizes", help="Particle counts, comma-separated."),
    threads: str = THREADS_OPTION,
    steps: int = typer.Option(200, "--steps", min=1, help="Steps per timing."),
    repeats: int = typer.Option(3, "--repeats", min=1, help="Timings per row (the median is reported)."),
    states: str = typer.Option("loose,settled", "--states", help="loose and/or settled."),
    output: Path = OUTPUT_OPTION,
    fixed_cost_sizes: str = typer.Option(
        "10,30,100,300,1000,3000,10000",
        "--fixed-cost-sizes",
        help="Particle counts of the fixed cost per step (an intercept; at least two, empty: none).",
    ),
) -> None:
    """Particle-steps per second on the canonical DEM scene, for each size, state and thread count,
    and the fixed cost of a step."""
    from .bench.dem import run_benchmark

    chosen = tuple(s.strip() for s in states.split(",") if s.strip())
    if not set(chosen) <= {"loose", "settled"}:
        raise typer.BadParameter(f"--states {states!r}: expected loose and/or settled")
    fixed = _numbers(fixed_cost_sizes, "--fixed-cost-sizes")
    if len(fixed) == 1:
        raise typer.BadParameter(f"--fixed-cost-sizes {fixed_cost_sizes!r}: a line needs two sizes or more")
    counts = _numbers(sizes, "--sizes"), _thread_counts(threads)
    _bench(lambda: run_benchmark(*counts, steps, repeats, chosen, output, fixed_cost_sizes=fixed), output)


@bench_app.command("gpu")
def bench_gpu(
    sizes: str = typer.Option("100000,1000000,10000000", "--sizes", help="Particle counts, comma-separated."),
    steps: int = typer.Option(200, "--steps", min=1, help="Steps per timing."),
    repeats: int = typer.Option(3, "--repeats", min=1, help="Timings per row (the median is reported)."),
    states: str = typer.Option("loose,settled", "--states", help="loose and/or settled."),
    walls: str = typer.Option(
        "fixed",
        "--walls",
        help="fixed and/or moving: moving adds loose rows whose lid keeps a stress and slides.",
    ),
    fluids: str = typer.Option(
        "none",
        "--fluids",
        help="none, navier-stokes and/or darcy: each fluid adds loose rows in water on its grid.",
    ),
    output: Path = OUTPUT_OPTION,
) -> None:
    """The DEM step on a CUDA GPU (simulation.device = "cuda") on the canonical scene: particle-steps
    per second, bytes on the GPU per particle, each kernel's share (needs a GPU and the CUDA extra)."""
    from .bench.gpu import run_gpu_benchmark

    chosen = tuple(s.strip() for s in states.split(",") if s.strip())
    if not set(chosen) <= {"loose", "settled"}:
        raise typer.BadParameter(f"--states {states!r}: expected loose and/or settled")
    lids = _lids(walls)
    media = tuple(s.strip() for s in fluids.split(",") if s.strip())
    if not media or not set(media) <= {"none", "navier-stokes", "darcy"}:
        raise typer.BadParameter(f"--fluids {fluids!r}: expected none, navier-stokes and/or darcy")
    counts = _numbers(sizes, "--sizes")
    _bench(
        lambda: run_gpu_benchmark(counts, steps, repeats, chosen, output, walls=lids, fluids=media), output
    )


@bench_app.command("ranks")
def bench_ranks(
    sizes: str = typer.Option("100000", "--sizes", help="Particle counts, comma-separated."),
    rank_counts: str = typer.Option(
        "1,2", "--ranks", help="MPI rank counts, comma-separated (the first is the base)."
    ),
    steps: int = typer.Option(
        300,
        "--steps",
        min=1,
        help="Steps per timing (300 hold a neighbour-list build or two at 100 000, as a run's steps do).",
    ),
    repeats: int = typer.Option(3, "--repeats", min=1, help="Timings per rank count and round (median)."),
    rounds: int = typer.Option(3, "--rounds", min=1, help="Rounds, the rank counts alternating."),
    walls: str = typer.Option(
        "fixed",
        "--walls",
        help="fixed and/or moving: moving puts the lid onto the bed, keeping a stress and sliding.",
    ),
    output: Path = OUTPUT_OPTION,
) -> None:
    """The settled canonical bed on several MPI ranks (one thread each), side by side: particle-steps
    per second and the speed-up over the first rank count, round by round (needs mpiexec)."""
    from .bench.ranks import run_ranks_benchmark

    counts, lids = _numbers(rank_counts, "--ranks"), _lids(walls)
    sized = _numbers(sizes, "--sizes")
    _bench(lambda: run_ranks_benchmark(sized, counts, steps, repeats, rounds, output, walls=lids), output)


@bench_app.command("ranks-member", hidden=True)
def bench_ranks_member(n: int, steps: int, repeats: int, lid: str = typer.Option("fixed", "--lid")) -> None:
    """One rank count of `sphere bench ranks` (started by it under mpiexec)."""
    from .bench.ranks import member

    _bench(lambda: member(n, steps, repeats, lid))


@bench_app.command("fluid")
def bench_fluid(
    cells: int = CELLS_OPTION,
    particles: int = PARTICLES_OPTION,
    threads: str = THREADS_OPTION,
    steps: int = COUPLED_STEPS_OPTION,
    jacobi_max_iterations: int = typer.Option(
        100_000, "--jacobi-max-iterations", min=1, help="Jacobi stops after this many."
    ),
    jacobi_seconds: float = typer.Option(
        60.0, "--jacobi-seconds", min=0.0, help="Jacobi stops after this many seconds."
    ),
    output: Path = OUTPUT_OPTION,
) -> None:
    """The Navier-Stokes fluid coupled to a DEM bed: cell-updates per second of the fluid step,
    time per coupled step, pressure-solve time of the fast solver and of Jacobi."""
    from .bench.fluid import run_fluid_benchmark

    counts = _thread_counts(threads)
    _bench(
        lambda: run_fluid_benchmark(
            cells, particles, counts, steps, jacobi_max_iterations, jacobi_seconds, output
        ),
        output,
    )


@bench_app.command("darcy")
def bench_darcy(
    cells: int = CELLS_OPTION,
    particles: int = PARTICLES_OPTION,
    threads: str = THREADS_OPTION,
    steps: int = COUPLED_STEPS_OPTION,
    tolerance: float = typer.Option(1e-8, "--tolerance", min=0.0, help="fluid.solver.tolerance."),
) -> None:
    """The Darcy model coupled to the DEM: one coupled step and its parts, with the solve's iterations."""
    from .bench.darcy import run_darcy_benchmark

    counts = _thread_counts(threads)
    _bench(lambda: run_darcy_benchmark(cells, particles, counts, steps, tolerance))


@bench_app.command("vans1d")
def bench_vans1d(
    case: Path = typer.Option(Path("configs/bedload.toml"), "--case", help="The vans1d case timed."),
    threads: str = THREADS_OPTION,
    simulated: float = typer.Option(0.05, "--time", min=0.0, help="Simulated seconds timed [s]."),
) -> None:
    """The 1D VANS bedload case: wall time per simulated second and the fluid's share of it."""
    from .bench.vans1d import run_vans1d_benchmark

    counts = _thread_counts(threads)
    _bench(lambda: run_vans1d_benchmark(case, counts, simulated))


@bench_app.command("compile")
def bench_compile(
    repeats: int = typer.Option(1, "--repeats", min=1, help="Fresh caches timed."),
    threads: str = THREADS_OPTION,
) -> None:
    """Seconds a dry scene waits for its kernels before the first step: cold (empty Numba cache)
    and cached, each in a fresh process, on each thread count."""
    from .bench.compile import run_compile_benchmark

    counts = _thread_counts(threads)
    _bench(lambda: run_compile_benchmark(repeats, counts))


@bench_app.command("grid")
def bench_grid(
    sizes: str = typer.Option("32,64", "--sizes", help="Cells along each axis, comma-separated."),
    threads: str = THREADS_OPTION,
    tolerance: float = typer.Option(1e-8, "--tolerance", min=0.0, help="Relative residual to reach."),
    repeats: int = typer.Option(3, "--repeats", min=1, help="Solves per row (the best is reported)."),
    methods: str = typer.Option(
        "pcg-multigrid,pcg-jacobi,jacobi", "--methods", help="Solvers, comma-separated."
    ),
    porosity: bool = typer.Option(False, "--porosity", help="Time the porosity estimate instead."),
) -> None:
    """The fluids' shared plumbing: the pressure solvers (iterations, time) or the porosity estimate."""
    from .bench.grid import METHODS, porosity_benchmark, solver_benchmark

    counts = _thread_counts(threads)
    if porosity:
        _bench(lambda: porosity_benchmark(counts))
        return
    chosen = tuple(m.strip() for m in methods.split(",") if m.strip())
    if not set(chosen) <= set(METHODS):
        raise typer.BadParameter(f"--methods {methods!r}: expected some of {', '.join(METHODS)}")
    _bench(lambda: solver_benchmark(_numbers(sizes, "--sizes"), counts, tolerance, repeats, chosen))


@app.command()
def verify(
    names: list[str] | None = typer.Argument(
        None, metavar="[CASE]...", help="Cases to run, by name or prefix (default: all)."
    ),
    quick: bool = typer.Option(False, "--quick", help="Short resolution ladders (seconds, not minutes)."),
    output: Path = typer.Option(
        Path("verify-results"), "-o", "--output", help="Folder for verify.json, the tables and the plots."
    ),
    list_cases: bool = typer.Option(False, "--list", help="List the cases and exit."),
    repeats: int = typer.Option(3, "--repeats", min=1, help="Timed runs per resolution (median reported)."),
) -> None:
    """Verification: each case at a ladder of resolutions, errors against the analytic or
    published reference beside wall time, observed orders of convergence, and the stability
    suite. Exit 0 when every case passes, 70 when one misses its tolerance or order (or a
    stability case does not refuse, run or report as it must)."""
    from .errors import NumericalError
    from .verify import all_names, run_verification

    if list_cases:
        for name, title in all_names().items():
            typer.echo(f"{name:36s} {title}")
        return
    try:
        _results_folder(output)
        report = run_verification(
            names, quick=quick, out_dir=output, repeats=repeats, log=lambda msg: typer.echo(msg, err=True)
        )
    except SphereError as exc:
        _fail(exc)
    except OSError as exc:  # the folder failed between the check and the writes
        _fail(OutputError(f"{output}: cannot write the results there ({exc.strerror or exc})"))
    for record in report["cases"]:
        orders = ", ".join(
            f"{m} {record['orders'][m]:.2f}"
            for m in record["order_metrics"]
            if record["orders"].get(m) is not None
        )
        typer.echo(
            f"{'pass' if record['passed'] else 'FAIL'}  {record['name']}"
            + (f"  (order {orders}; formal {record['formal_order']:g})" if orders else "")
        )
    for record in report["stability"]:
        typer.echo(f"{'pass' if record['passed'] else 'FAIL'}  {record['name']}  ({record['action']})")
    for note in report["notes"]:
        typer.echo(f"note: {note}", err=True)
    typer.echo(f"results: {output}/verify.json, {output}/*.md ({report['total_s']:.0f} s)")
    if not report["passed"]:
        typer.echo(f"sphere: verification failed: {', '.join(report['failed'])}", err=True)
        raise typer.Exit(NumericalError.exit_code)


@app.command()
def sweep(
    case: Path = typer.Argument(
        ..., metavar="CASE", help="Case file (TOML), or the folder of a sweep made before (to run it on)."
    ),
    vary: list[str] | None = typer.Option(
        None,
        "--vary",
        metavar="KEY=VALUES",
        help="A key and its values: particles.seed=1..32 (integers, both ends), contact.friction=0.3,0.5 "
        "(TOML values separated by commas). Repeat for more keys: every combination is a member.",
    ),
    zipped: bool = typer.Option(
        False, "--zip", help="Pair the values of the --vary options (the i-th of each) instead of combining."
    ),
    output: Path | None = typer.Option(
        None, "-o", "--output", help="Sweep folder (default runs/<case name>-sweep)."
    ),
    local: int | None = typer.Option(
        None, "--local", min=1, metavar="N", help="Run the members not done here, N processes at a time."
    ),
    threads: int | None = typer.Option(
        None,
        "--threads",
        min=1,
        metavar="T",
        help="Threads per member (default: 1 in the SLURM script; with --local, the cores shared out).",
    ),
) -> None:
    """Run one case many times with keys varied: write each member's case and run directory and a
    SLURM job array (sweep.sbatch), and with --local run the members here. Run it again to
    continue: members done are skipped, stopped or killed ones resume from their checkpoints."""
    from . import sweep as sweeps

    made = None
    try:
        if case.is_dir() and (case / sweeps.SWEEP_FILE).is_file():
            if vary:
                raise UsageError(f"{case}: is a sweep already; give its case file to make one with --vary")
            made = sweeps.Sweep.load(case)
        else:
            varies = [sweeps.parse_vary(text) for text in vary or []]
            made = sweeps.create(case, varies, zipped, output, threads)
        typer.echo(f"sweep: {len(made.names)} members in {made.path} (members.csv lists their values)")
        if local is None:
            typer.echo(
                f"run them: sbatch {made.path}/sweep.sbatch, or here: sphere sweep {made.path} --local N\n"
                f"results: sphere sweep-summary {made.path}"
            )
            return
        per_member = threads or max(1, usable_cores() // local)
        stop = StopFlag()
        with signal_handlers(stop, True):
            code = sweeps.run_local(
                made, local, per_member, stop, log=lambda line: typer.echo(f"sweep: {line}")
            )
        typer.echo(f"sweep: summary in {sweeps.write_summary(made, sweeps.summary(made))}")
    except SphereError as exc:
        _fail(exc)
    except KeyboardInterrupt:
        again = "" if made is None else f"; continue with: sphere sweep {made.path} --local {local or 'N'}"
        typer.echo(f"sphere: interrupted{again}", err=True)
        raise typer.Exit(StoppedEarly.exit_code) from None
    if code == StoppedEarly.exit_code:
        typer.echo(
            f"sphere: sweep stopped; continue with: sphere sweep {made.path} --local {local}", err=True
        )
    elif code:
        typer.echo("sphere: some members did not finish (see their logs above)", err=True)
    raise typer.Exit(code)


@app.command("sweep-member")
def sweep_member(
    sweep_dir: Path = typer.Argument(..., metavar="SWEEP_DIR", help="Folder made by `sphere sweep`."),
    member: str = typer.Argument(..., metavar="MEMBER", help="Member name (m003) or index (3)."),
    max_wall_time: str | None = typer.Option(None, "--max-wall-time", help=WALL_TIME_HELP),
    requeue: bool = typer.Option(
        False,
        "--requeue",
        help="In a SLURM job: when stopped by SIGUSR1 or --max-wall-time, requeue the task (scontrol) "
        "and exit 0.",
    ),
    quiet: bool = typer.Option(False, "-q", "--quiet", help="No progress output."),
) -> None:
    """Run one member of a sweep: start it, continue it from its checkpoint, or, if it is done,
    nothing (what each task of sweep.sbatch runs)."""
    from . import sweep as sweeps

    try:
        made = sweeps.Sweep.load(sweep_dir)
        name = made.member(member)
        result = sweeps.run_member(
            made,
            name,
            max_wall_time=_wall_time(max_wall_time),
            handle_signals=True,
            show_progress=not quiet,
        )
    except StoppedEarly as exc:
        if requeue and not (exc.reason or "").startswith(("SIGTERM", "SIGINT")):
            problem = sweeps.requeue_task()
            if problem is None:
                typer.echo(f"sphere: {exc}; task requeued", err=True)
                raise typer.Exit(0) from None
            typer.echo(f"sphere: {problem}", err=True)
        _fail(exc)
    except SphereError as exc:
        _fail(exc)
    except KeyboardInterrupt:
        _interrupted()
    if result is None:
        typer.echo(f"{name}: done already ({made.run_dir(name)})")
    else:
        _report(result)


@app.command("sweep-summary")
def sweep_summary(
    sweep_dir: Path = typer.Argument(..., metavar="SWEEP_DIR", help="Folder made by `sphere sweep`."),
    as_json: bool = typer.Option(False, "--json", help="Print the table as JSON."),
) -> None:
    """Each member's values, state and last observables, as one table (SWEEP_DIR/summary.csv)."""
    from . import sweep as sweeps

    try:
        made = sweeps.Sweep.load(sweep_dir)
        rows = sweeps.summary(made)
        path = sweeps.write_summary(made, rows)
    except SphereError as exc:
        _fail(exc)
    if as_json:
        typer.echo(json_text(rows))
        return
    states = {}
    for row in rows:
        states[row["state"]] = states.get(row["state"], 0) + 1
    for row in rows:
        progress = f"step {row['step']}/{row['end_step']}" if row["step"] is not None else ""
        values = ", ".join(f"{v.key} = {row[v.key]}" for v in made.varies)
        typer.echo(f"{row['member']}  {row['state']:<11}  {progress:<20}  {values}")
    typer.echo(", ".join(f"{count} {state}" for state, count in states.items()) + f"; table: {path}")


def _interrupted() -> None:
    typer.echo(
        "sphere: interrupted; the newest checkpoint is intact: continue with `sphere resume`", err=True
    )
    raise typer.Exit(StoppedEarly.exit_code)


def _report(result: api.RunResult) -> None:
    rate = f"{result.particle_steps_per_second / 1e6:.2f} M particle-steps/s"
    if result.particle_steps_per_second == 0.0:  # no particles
        rate = f"{result.steps_per_second:.3g} steps/s"
    if result.steps_per_second == 0.0:  # the rate leaves the first step out (it compiles)
        rate = "too few steps to time"
    sidecar = result.run_dir / "trajectory.xmf"  # none for a run with nothing to show in ParaView
    shown = f" (open {sidecar} in ParaView)" if sidecar.is_file() else ""
    # a first run of a case compiles its kernels: say so, or the run looks that slow
    compiling = result.compiling_seconds
    spent = f" ({compiling:.1f} s of it compiling kernels, cached for later runs)" if compiling >= 1.0 else ""
    typer.echo(
        f"done: t = {result.time:.6g} s (step {result.step}) in {result.wall_seconds:.1f} s{spent}, {rate}\n"
        f"output: {result.run_dir}/trajectory.h5{shown}, checkpoints in {result.run_dir}/checkpoints/"
    )


def main() -> None:
    guard_console()  # a console that goes away does not end a run (io/console.py)
    try:
        app()
    except KeyboardInterrupt:
        sys.exit(StoppedEarly.exit_code)


if __name__ == "__main__":
    main()
