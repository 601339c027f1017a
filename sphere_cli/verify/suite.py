"""`sphere verify` as a library function: run the chosen verification and stability cases,
write verify.json, the tables and the plots, and say whether everything passed."""

from __future__ import annotations

import os
import platform
import subprocess
import time
from datetime import UTC, datetime
from pathlib import Path

from ..errors import UsageError
from .registry import cases
from .report import SCHEMA, write_outputs
from .runner import run_case
from .stability import STABILITY, run_stability_case

THREADS = 1  # the scenes hold 1-6 particles: a parallel region costs more than it saves


def all_names() -> dict[str, str]:
    """name -> title of every verification and stability case, in run order."""
    names = {name: case.title for name, case in cases().items()}
    names.update({name: case.title for name, case in STABILITY.items()})
    return names


def select(names: list[str] | None) -> tuple[list[str], list[str]]:
    """(verification case names, stability case names) to run; a name may also be a prefix
    ("a1", "stability"). Unknown names are a UsageError."""
    known_cases, known_stability = list(cases()), list(STABILITY)
    if not names:
        return known_cases, known_stability
    chosen: list[str] = []
    for name in names:
        matches = [n for n in known_cases + known_stability if n == name or n.startswith(name)]
        if not matches:
            raise UsageError(f"unknown verification case {name!r}; `sphere verify --list` shows them all")
        chosen += [m for m in matches if m not in chosen]
    return [n for n in known_cases if n in chosen], [n for n in known_stability if n in chosen]


def _git_commit() -> str | None:
    """The last commit that changed the package (sphere_cli/), '-dirty' with uncommitted
    changes there: what the numbers belong to (a report committed later names its code)."""
    root = Path(__file__).resolve().parents[2]
    package = str(root / "sphere_cli")
    try:
        head = subprocess.run(
            ["git", "-C", str(root), "log", "-1", "--format=%h", "--", package],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no", "--", package],
            capture_output=True,
            text=True,
            timeout=10,
            check=True,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return None
    return head + ("-dirty" if dirty else "") if head else None


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine()


def machine() -> dict:
    """What produced the numbers: host, cores, thread count, versions."""
    import numba
    import numpy

    from ..io.provenance import _version
    from ..runtime import usable_cores

    usable = usable_cores()
    try:
        layer = numba.threading_layer()
    except ValueError:  # no parallel kernel has run yet
        layer = None
    return {
        "host": platform.node(),
        "platform": platform.platform(),
        "processor": _cpu_model(),
        "cpus": os.cpu_count(),
        "cpus_usable": usable,
        "threads": THREADS,
        "threading_layer": layer,
        "python": platform.python_version(),
        "numba": numba.__version__,
        "numpy": numpy.__version__,
        "sphere": _version("sphere-cli"),
        "commit": _git_commit(),
    }


def run_verification(
    names: list[str] | None = None,
    quick: bool = False,
    out_dir: str | Path = "verify-results",
    repeats: int = 3,
    plots: bool = True,
    log=None,
) -> dict:
    """Run the chosen cases (all by default) and write the outputs to out_dir.

    Returns the report (the content of verify.json); report["passed"] is False if any case
    missed a tolerance, fell short of its order, or any stability case did not do what it must.
    """
    import numba

    say = log or (lambda _msg: None)
    if repeats < 1:
        raise UsageError("repeats must be >= 1")
    case_names, stability_names = select(names)
    registry = cases()
    previous = numba.get_num_threads()
    numba.set_num_threads(min(THREADS, numba.config.NUMBA_NUM_THREADS))
    started = time.perf_counter()
    try:
        records = []
        for name in case_names:
            say(f"{name}: {registry[name].title}")
            records.append(run_case(registry[name], quick=quick, repeats=repeats, log=say))
            say(f"  -> {'pass' if records[-1]['passed'] else 'FAIL'}")
        stability = []
        for name in stability_names:
            say(f"{name}: {STABILITY[name].title}")
            stability.append(run_stability_case(STABILITY[name], quick=quick))
            say(f"  -> {'pass' if stability[-1]['passed'] else 'FAIL'} ({stability[-1]['action']})")
    finally:
        numba.set_num_threads(previous)
    report = {
        "schema": SCHEMA,
        "date": datetime.now(UTC).isoformat(timespec="seconds"),
        "mode": "quick" if quick else "full",
        "repeats": repeats,
        "machine": machine(),
        "total_s": time.perf_counter() - started,
        "passed": all(r["passed"] for r in records) and all(s["passed"] for s in stability),
        "failed": [r["name"] for r in records if not r["passed"]]
        + [s["name"] for s in stability if not s["passed"]],
        "cases": records,
        "stability": stability,
    }
    write_outputs(report, Path(out_dir), plots=plots)
    return report
