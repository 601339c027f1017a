"""Ensembles: one case run many times with some of its keys varied (`sphere sweep`).

A sweep is a folder (SWEEP_DIR):

    sweep.json        what the sweep is: the base case (its path and the SHA-256 of its text),
                      the keys varied and their values, the members' names (written last)
    members.csv       one row per member: its name and the value of each varied key
    cases/<m>.toml    each member's case: the base case with the member's values
    runs/<m>/         each member's run directory (`sphere run`'s)
    logs/<m>.log      what a member printed when run by `--local` (SLURM writes %x-%A_%a.out)
    sweep.sbatch      a SLURM job array, one task per member
    summary.csv       written by `sphere sweep-summary`

A member is idempotent: `sphere sweep-member SWEEP_DIR m` starts it, continues it from its
newest checkpoint, or does nothing when it is done, so the same command serves a first start, a
requeued array task and a sweep run again after a kill. Relative paths in the base case
(placement files, pressure series) resolve from the base case's folder, as for the base case
itself. Members never share a file: each writes its own run directory under its own lock.
"""

from __future__ import annotations

import copy
import csv
import ctypes
import dataclasses
import hashlib
import io
import itertools
import json
import math
import os
import re
import shlex
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import tomli

from .config.consistency import case_warnings
from .config.load import load_case, parse_case, render_toml, toml_text, warn
from .errors import (
    CaseError,
    MissingInputError,
    NumericalError,
    OutputError,
    ResumeRefused,
    RunBusy,
    StoppedEarly,
    UsageError,
)
from .io.atomic import write_text_atomic
from .io.rundir import RunDirectory
from .runtime import usable_cores

SWEEP_FILE = "sweep.json"
FORMAT = 1
# SLURM's default MaxArraySize is 1001 (task ids 0..1000): a larger sweep is warned of, and its
# script submitted in parts with SWEEP_OFFSET
SLURM_ARRAY_LIMIT = 1001
ARRAY_PART = 1000  # members per submission of a larger sweep
# Each member is a case file and a run directory, and the members' cases are checked in memory
# before any is written: a sweep larger than this (a range typed with extra zeros, the product
# of several long --vary) is refused before anything is expanded or written.
MAX_MEMBERS = 100_000
# characters a sweep folder's path may not hold: #SBATCH lines cannot quote them
UNSAFE_PATH_CHARACTERS = '"\\\n#'
# what an interrupted `sphere sweep` may have left before its sweep.json: it may go on there
OWN_ENTRIES = {"cases", "runs", "logs", "members.csv", "sweep.sbatch"} | {
    f".{name}.tmp" for name in ("members.csv", "sweep.sbatch", SWEEP_FILE)
}
POLL_SECONDS = 0.1  # how often --local looks at its members
MAX_COLUMNS = 24  # an observable of more values (a profile) is left out of the summary table
_KEY_PART = re.compile(r"[A-Za-z0-9_-]+")
_BARE_WORD = re.compile(r"[^\s,\"'\[\]{}=]+")  # a string value given without quotes: z+, hertz-mindlin
_RANGE = re.compile(r"\s*(-?\d+)\s*\.\.\s*(-?\d+)\s*")

# the states of a member (member_state)
NOT_STARTED, RUNNING, INTERRUPTED, STOPPED, DONE, FAILED = (
    "not started",
    "running",
    "interrupted",
    "stopped",
    "done",
    "failed",
)


@dataclass(frozen=True)
class Vary:
    """One --vary: a dotted key of the case (a number indexes an array of tables: walls.0.velocity)
    and its values, each a TOML value."""

    key: str
    values: tuple

    @property
    def parts(self) -> tuple:
        return tuple(int(p) if p.isdigit() else p for p in self.key.split("."))


def parse_vary(text: str) -> Vary:
    """KEY=VALUES: `particles.seed=1..32` (integers, both ends included), `contact.friction=0.3,0.5`
    (TOML values separated by commas: numbers, true/false, "strings", [arrays]; a bare word is a
    string)."""
    key, sep, values = text.partition("=")
    key = key.strip()
    where = f"--vary {text!r}"
    if not sep or not key:
        raise UsageError(f"{where}: expected KEY=VALUES, e.g. particles.seed=1..8 or contact.friction=0.5,1")
    if not all(_KEY_PART.fullmatch(p) for p in key.split(".")):
        raise UsageError(f"{where}: {key!r} is not a dotted key of the case, e.g. contact.friction")
    span = _RANGE.fullmatch(values)
    if span:
        first, last = int(span.group(1)), int(span.group(2))
        if last < first:
            raise UsageError(f"{where}: the range {first}..{last} is empty (expected first <= last)")
        if last - first + 1 > MAX_MEMBERS:
            raise UsageError(
                f"{where}: the range {first}..{last} has {last - first + 1} values; a sweep has at "
                f"most {MAX_MEMBERS} members"
            )
        return Vary(key, tuple(range(first, last + 1)))
    parsed = _toml_values(values)
    if parsed is None:
        raise UsageError(
            f"{where}: {values!r} is not a list of values; expected FIRST..LAST (integers) or values "
            'separated by commas: 0.3,0.5 or "hertz","linear" or [0,0,-9.81],[0,0,-1.62]'
        )
    return Vary(key, parsed)


def _toml_values(text: str) -> tuple | None:
    """The values of `a,b,c` as TOML would read `[a,b,c]`; failing that, item by item, each a
    TOML value or else a bare word read as a string (`hertz,linear`; `auto,1e-6` is "auto" and
    the number 1e-6). None if there is nothing usable."""
    if not text.strip():
        return None
    try:
        return tuple(tomli.loads(f"v = [{text}]")["v"])
    except tomli.TOMLDecodeError:
        pass
    values = []
    for item in (item.strip() for item in text.split(",")):
        try:
            values.append(tomli.loads(f"v = {item}")["v"])
        except tomli.TOMLDecodeError:
            if not _BARE_WORD.fullmatch(item):
                return None
            values.append(item)
    return tuple(values)


def combinations(varies: list[Vary], zipped: bool) -> list[tuple]:
    """The members' values: every combination (the first --vary slowest), or with `zipped` the
    i-th value of every --vary together."""
    if zipped:
        lengths = {len(v.values) for v in varies}
        if len(lengths) > 1:
            counts = ", ".join(f"{v.key}: {len(v.values)}" for v in varies)
            raise UsageError(f"--zip needs as many values for every --vary ({counts})")
        return list(zip(*(v.values for v in varies), strict=True))
    count = math.prod(len(v.values) for v in varies)
    if count > MAX_MEMBERS:
        counts = " x ".join(f"{len(v.values)} ({v.key})" for v in varies)
        raise UsageError(f"--vary: {counts} = {count} members; a sweep has at most {MAX_MEMBERS}")
    return list(itertools.product(*(v.values for v in varies)))


def set_key(data: dict, vary: Vary, value) -> None:
    """Set the key `vary` names in the case's tables (missing tables are made; a number picks an
    element of an array of tables, which must exist)."""
    node = data
    parts = vary.parts
    for depth, part in enumerate(parts):
        last = depth == len(parts) - 1
        here = ".".join(str(p) for p in parts[:depth]) or "the case"
        if isinstance(part, int):
            if not isinstance(node, list) or part >= len(node):
                size = f"{len(node)} entries" if isinstance(node, list) else "no array of tables"
                raise UsageError(f"--vary {vary.key}: {here} has {size}; index {part} does not exist")
        elif not isinstance(node, dict):
            raise UsageError(f"--vary {vary.key}: {here} is a value, not a table with key {part!r}")
        if last:
            node[part] = value
        elif isinstance(part, int):
            node = node[part]
        else:
            node = node.setdefault(part, {})


def member_names(count: int) -> list[str]:
    width = max(3, len(str(count - 1)))
    return [f"m{k:0{width}d}" for k in range(count)]


@dataclass
class Sweep:
    path: Path
    base_case: Path  # absolute
    base_sha256: str
    varies: list[Vary]
    zipped: bool
    names: list[str]
    values: list[tuple]

    def case_path(self, name: str) -> Path:
        return self.path / "cases" / f"{name}.toml"

    def run_dir(self, name: str) -> Path:
        return self.path / "runs" / name

    def log_path(self, name: str) -> Path:
        return self.path / "logs" / f"{name}.log"

    def member(self, which: str) -> str:
        """A member's name from its name or index (what SLURM_ARRAY_TASK_ID gives)."""
        if which.isdigit() and int(which) < len(self.names):
            return self.names[int(which)]
        if which in self.names:
            return which
        raise UsageError(
            f"{self.path}: no member {which!r}; members are {self.names[0]}..{self.names[-1]} "
            f"(or their indices 0..{len(self.names) - 1})"
        )

    def manifest(self) -> dict:
        return {
            "sphere_sweep": FORMAT,
            "base_case": str(self.base_case),
            "base_case_sha256": self.base_sha256,
            "zip": self.zipped,
            "vary": [{"key": v.key, "values": list(v.values)} for v in self.varies],
            "members": [
                {"name": name, "values": dict(zip((v.key for v in self.varies), values, strict=True))}
                for name, values in zip(self.names, self.values, strict=True)
            ],
        }

    @classmethod
    def load(cls, path: Path) -> Sweep:
        file = Path(path) / SWEEP_FILE
        try:
            data = json.loads(file.read_text(encoding="utf-8"))
            varies = [Vary(v["key"], tuple(v["values"])) for v in data["vary"]]
            names = [m["name"] for m in data["members"]]
            values = [tuple(m["values"][v.key] for v in varies) for m in data["members"]]
            return cls(
                Path(path),
                Path(data["base_case"]),
                data["base_case_sha256"],
                varies,
                data["zip"],
                names,
                values,
            )
        except (FileNotFoundError, NotADirectoryError):
            what = (
                "a file, not the folder `sphere sweep` makes" if Path(path).is_file() else f"no {SWEEP_FILE}"
            )
            raise MissingInputError(f"{path}: not a sweep directory ({what})") from None
        except (ValueError, KeyError, TypeError) as exc:  # a file holding nothing usable (66)
            raise MissingInputError(
                f"{file}: not a sweep description sphere wrote ({type(exc).__name__}: {exc})"
            ) from None
        except OSError as exc:
            raise OutputError(f"{file}: unreadable ({type(exc).__name__}: {exc})") from None


def create(
    case: Path, varies: list[Vary], zipped: bool, out: Path | None, threads: int | None = None
) -> Sweep:
    """Write the sweep's folder (or find the same sweep already there): every member's case is
    checked before anything is written."""
    from .scene.builder import check_build

    if not varies:
        raise UsageError("sphere sweep: give at least one --vary KEY=VALUES")
    keys = [v.key for v in varies]
    if len(set(keys)) < len(keys):
        raise UsageError(f"--vary: a key is given twice ({', '.join(keys)})")
    base = load_case(case)
    base_path = Path(case).resolve()
    data = tomli.loads(base.text)
    out = Path(out) if out is not None else Path("runs") / f"{Path(case).stem}-sweep"
    awkward = set(str(out.resolve())) & set(UNSAFE_PATH_CHARACTERS)
    if awkward:
        raise UsageError(
            f"{out}: a sweep folder's path may not hold {' '.join(sorted(map(repr, awkward)))}: the SLURM "
            "script names it in #SBATCH lines; choose another with -o"
        )
    values = combinations(varies, zipped)
    if len(values) > SLURM_ARRAY_LIMIT:
        warn(
            f"{len(values)} members: more task ids than SLURM's usual MaxArraySize ({SLURM_ARRAY_LIMIT}); "
            "sweep.sbatch says how to submit the rest (SWEEP_OFFSET)"
        )
    names = member_names(len(values))
    digest = hashlib.sha256(base.text.encode()).hexdigest()
    sweep = Sweep(out, base_path, digest, varies, zipped, names, values)
    shown = {(loc, message) for loc, message in case_warnings(base.case)}
    texts = {}
    files: dict = {}  # the placement files read so far: the members share them, read once
    for name, member_values in zip(names, values, strict=True):
        member = copy.deepcopy(data)
        for vary, value in zip(varies, member_values, strict=True):
            set_key(member, vary, value)
        setting = ", ".join(f"{v.key} = {toml_text(x)}" for v, x in zip(varies, member_values, strict=True))
        text = (
            f"# sweep member {name}: {setting}\n"
            f"# written by `sphere sweep` from {base_path}; relative paths resolve from that folder\n\n"
            + render_toml(member)
        )
        try:
            loaded = parse_case(text, sweep.case_path(name), show_warnings=False)
            check_build(dataclasses.replace(loaded, origin=base_path), files)  # the base's files
        except CaseError as exc:
            raise CaseError(f"sweep member {name} ({setting}): {exc}") from None
        for loc, message in case_warnings(loaded.case):
            if (loc, message) not in shown:
                shown.add((loc, message))
                warn(f"sweep member {name} ({setting}): {'.'.join(map(str, loc))}: {message}")
        texts[name] = text
    _write(sweep, texts, threads)
    return sweep


def _write(sweep: Sweep, texts: dict[str, str], threads: int | None) -> None:
    manifest = sweep.manifest()
    file = sweep.path / SWEEP_FILE
    if file.is_file():
        old = Sweep.load(sweep.path).manifest()
        if json.dumps(old) != json.dumps(manifest):  # as text: a nan value equals itself
            changed = [k for k in manifest if manifest[k] != old.get(k)]
            raise ResumeRefused(
                f"{sweep.path}: holds another sweep (differs in: {', '.join(changed)}); its members "
                "are kept. Choose another folder with -o, or remove this one to start again."
            )
    # a new sweep writes everything, also over what an interrupted `sphere sweep` left (its cases
    # may be another sweep's); a sweep found again keeps its cases and its (edited) script
    fresh = not file.is_file()
    if fresh and sweep.path.exists():
        if not sweep.path.is_dir() or not {e.name for e in sweep.path.iterdir()} <= OWN_ENTRIES:
            raise OutputError(f"{sweep.path}: exists and is not a sweep folder; choose another with -o")
    try:
        for sub in ("cases", "runs", "logs"):
            (sweep.path / sub).mkdir(parents=True, exist_ok=True)
        for name, text in texts.items():
            if fresh or not sweep.case_path(name).is_file():
                write_text_atomic(sweep.case_path(name), text)
        table = io.StringIO()
        rows = csv.writer(table, lineterminator="\n")
        rows.writerow(["member", *(v.key for v in sweep.varies)])
        for name, values in zip(sweep.names, sweep.values, strict=True):
            rows.writerow([name, *(_cell(x) for x in values)])
        write_text_atomic(sweep.path / "members.csv", table.getvalue())
        script = sweep.path / "sweep.sbatch"
        if fresh or not script.is_file():  # then kept as it is: users edit its #SBATCH lines
            write_text_atomic(script, sbatch_script(sweep, threads or 1))
            script.chmod(0o755)
        elif threads is not None and f"--cpus-per-task={threads}\n" not in script.read_text(encoding="utf-8"):
            warn(f"{script}: kept as it is; its --cpus-per-task is not {threads} (edit it, or remove it)")
        write_text_atomic(file, json.dumps(manifest, indent=2) + "\n")
    except OSError as exc:
        raise OutputError(f"{sweep.path}: cannot write the sweep ({exc})") from None


def _cell(value) -> str:
    """A value in a CSV cell: a string as it is, anything else as TOML writes it."""
    return value if isinstance(value, str) else toml_text(value)


def sbatch_script(sweep: Sweep, threads: int) -> str:
    """A SLURM job array running every member: `sbatch SWEEP_DIR/sweep.sbatch`. SIGUSR1 before
    the time limit reaches sphere itself (exec), which checkpoints and requeues the task."""
    path = sweep.path.resolve()
    name = re.sub(r"[^A-Za-z0-9_.-]", "_", sweep.base_case.stem)
    count = len(sweep.names)
    last = (count if count <= SLURM_ARRAY_LIMIT else ARRAY_PART) - 1
    more = ""
    if count > SLURM_ARRAY_LIMIT:
        more = (
            f"# {count} members: more task ids than SLURM's usual MaxArraySize ({SLURM_ARRAY_LIMIT}) "
            f"allows. The array\n# below runs members 0-{ARRAY_PART - 1}; then, and so on: sbatch "
            f"--array=0-{ARRAY_PART - 1} --export=ALL,SWEEP_OFFSET={ARRAY_PART} sweep.sbatch\n"
        )
    output = str(path / "logs").replace("%", "%%") + "/%x-%A_%a.out"  # sbatch expands % patterns
    return f"""#!/bin/bash
# The members of the sweep in {path} as a SLURM job array, one task per member
# (written by `sphere sweep`; docs/user-guide.md, section 7):
#   sbatch {path}/sweep.sbatch                    every member
#   sbatch --array=3,7 {path}/sweep.sbatch        members 3 and 7 only
# Each task starts its member, continues it from its newest checkpoint, or ends at once if it is
# done. SIGUSR1, 300 s before the time limit, makes the member checkpoint and requeue its task;
# scancel's SIGTERM makes it checkpoint and stop. Collect the results: sphere sweep-summary {path}
{more}#SBATCH --job-name={name}-sweep
#SBATCH --array=0-{last}
#SBATCH --ntasks=1
#SBATCH --cpus-per-task={threads}
#SBATCH --time=24:00:00
#SBATCH --signal=B:USR1@300
#SBATCH --requeue
#SBATCH --open-mode=append
#SBATCH --output="{output}"

set -eu
# exactly the CPUs SLURM gave the task (the results do not depend on the count)
export NUMBA_NUM_THREADS="${{SLURM_CPUS_PER_TASK:-1}}"
export OMP_NUM_THREADS="$NUMBA_NUM_THREADS"
export OMP_WAIT_POLICY="${{OMP_WAIT_POLICY:-ACTIVE}}"
# the Python that has sphere installed (set SPHERE_PYTHON to use another)
made_with={shlex.quote(sys.executable)}
SPHERE_PYTHON="${{SPHERE_PYTHON:-$made_with}}"
task="${{SLURM_ARRAY_TASK_ID:?submit this script with sbatch: it is a job array}}"
task=$((task + ${{SWEEP_OFFSET:-0}}))
if [ "$task" -ge {count} ]; then
    exit 0  # past the last member (the last part of a sweep submitted with SWEEP_OFFSET)
fi
exec "$SPHERE_PYTHON" -m sphere_cli sweep-member {shlex.quote(str(path))} "$task" --requeue --quiet
"""


def member_state(sweep: Sweep, name: str) -> tuple[str, dict]:
    """(state, status.json) of a member: not started, running (its run directory is locked),
    interrupted (killed: no process holds it, its status says it was running; or stopped by its
    files, a full disk: it continues from its checkpoint once they can be written), stopped (a
    stop request; it continues from its checkpoint), done, failed (the integration failed)."""
    rundir = RunDirectory(sweep.run_dir(name))
    if not rundir.is_run():
        return NOT_STARTED, {}
    # the lock first: a member that ends between the two readings is then seen running, not
    # (from its last status while running) interrupted
    running = rundir.busy()
    status = rundir.read_status()
    if running:
        return RUNNING, status
    state = status.get("state")
    if state == "done" and status.get("step") == status.get("end_step"):
        return DONE, status
    if state == "failed" and status.get("exit_code") != OutputError.exit_code:
        return FAILED, status
    if state == "stopped":
        return STOPPED, status
    return INTERRUPTED, status


def run_member(sweep: Sweep, name: str, **options):
    """Start, continue or leave alone (done) one member; the api's RunResult, or None if it was
    done already."""
    from . import api

    state, status = member_state(sweep, name)
    if state == DONE:
        return None
    if state == FAILED:
        raise NumericalError(
            f"sweep member {name} failed before ({status.get('error', 'see its run.log')}); it would "
            f"fail again: remove {sweep.run_dir(name)} to run it anew"
        )
    if state == RUNNING:
        raise RunBusy(f"sweep member {name} is running in another process ({sweep.run_dir(name)})")
    if RunDirectory(sweep.run_dir(name)).is_run():
        return api.resume(sweep.run_dir(name), **options)
    return api.run(sweep.case_path(name), sweep.run_dir(name), origin=sweep.base_case, **options)


def requeue_task() -> str | None:
    """Requeue this SLURM array task (or job) with scontrol; an error message, or None if done."""
    job = os.environ.get("SLURM_JOB_ID")
    if os.environ.get("SLURM_ARRAY_TASK_ID") and os.environ.get("SLURM_ARRAY_JOB_ID"):
        job = f"{os.environ['SLURM_ARRAY_JOB_ID']}_{os.environ['SLURM_ARRAY_TASK_ID']}"
    if not job:
        return "not inside a SLURM job (no SLURM_JOB_ID)"
    try:
        done = subprocess.run(["scontrol", "requeue", job], capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired) as exc:
        return f"scontrol requeue {job} failed ({exc})"
    if done.returncode != 0:
        return f"scontrol requeue {job} failed (exit {done.returncode}): {done.stderr.strip()}"
    return None


def _die_with_parent(parent: int):
    """The member's first act (Linux): SIGTERM when `sphere sweep --local` dies, so that a killed
    sweep leaves no member running on (on SIGTERM a member checkpoints and exits 75); a parent
    already gone before that is seen by the parent's id."""

    def arrange() -> None:
        if sys.platform.startswith("linux"):
            ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
            if os.getppid() != parent:
                os._exit(75)

    return arrange


def _start(sweep: Sweep, name: str, env: dict) -> tuple[subprocess.Popen, object]:
    command = [sys.executable, "-m", "sphere_cli", "sweep-member", str(sweep.path), name, "-q"]
    try:
        out = sweep.log_path(name).open("ab")
    except OSError as exc:
        raise OutputError(f"{sweep.log_path(name)}: cannot open the member's log ({exc})") from None
    try:
        return subprocess.Popen(
            command, stdout=out, stderr=subprocess.STDOUT, env=env, preexec_fn=_die_with_parent(os.getpid())
        ), out
    except OSError as exc:
        out.close()
        raise OutputError(f"cannot start sweep member {name} ({exc})") from None


def run_local(sweep: Sweep, processes: int, threads: int, stop, log=print) -> int:
    """Run every member not done, `processes` at a time with `threads` threads each; after a
    stop request (stop.reason set) the running members are told to checkpoint (SIGTERM) and no
    new one starts. Returns the exit code: 0 when every member is done, 75 when stopped or when
    members run elsewhere (run the sweep again), else the first member's non-zero code (a member
    killed by signal N: 128 + N)."""
    pending, codes = [], {}
    for name in sweep.names:
        state, _ = member_state(sweep, name)
        if state == FAILED:
            codes[name] = NumericalError.exit_code
            log(f"{name}: failed before; not run again (remove {sweep.run_dir(name)} to retry)")
        elif state == RUNNING:
            codes[name] = StoppedEarly.exit_code
            log(f"{name}: running in another process; left to it")
        elif state != DONE:
            pending.append(name)
    done_before = len(sweep.names) - len(pending) - len(codes)
    log(f"{len(sweep.names)} members: {done_before} done, {len(pending)} to run, {processes} at a time")
    env = dict(os.environ, NUMBA_NUM_THREADS=str(threads), OMP_NUM_THREADS=str(threads))
    if processes * threads > usable_cores():
        # spinning OpenMP threads on shared cores are many times slower (docs/performance.md)
        env["OMP_WAIT_POLICY"] = "PASSIVE"
    running: dict[str, tuple[subprocess.Popen, object]] = {}
    told = False
    try:
        while pending or running:
            while pending and len(running) < processes and stop.reason is None:
                name = pending.pop(0)
                running[name] = _start(sweep, name, env)
            if stop.reason is not None and not told:
                told = True
                pending.clear()
                log(f"{stop.reason}: the running members write a checkpoint and stop")
                for proc, _ in running.values():
                    proc.send_signal(signal.SIGTERM)
            time.sleep(POLL_SECONDS)
            for name in [n for n, (proc, _) in running.items() if proc.poll() is not None]:
                proc, out = running.pop(name)
                out.close()
                code = proc.returncode if proc.returncode >= 0 else 128 - proc.returncode
                codes[name] = code
                log(f"{name}: " + ("done" if code == 0 else f"exit {code}, see {sweep.log_path(name)}"))
    finally:
        for proc, out in running.values():
            proc.send_signal(signal.SIGTERM)
            proc.wait()
            out.close()
    if stop.reason is not None:
        return StoppedEarly.exit_code
    return next((codes[n] for n in sweep.names if codes.get(n)), 0)


def summary(sweep: Sweep) -> list[dict]:
    """One row per member: its name, varied values, state, progress and the last value of each
    of its observables (numbers; a small tensor as one column per component)."""
    from .io.inspect import last_observables

    rows = []
    for name, values in zip(sweep.names, sweep.values, strict=True):
        state, status = member_state(sweep, name)
        row = {"member": name, **dict(zip((v.key for v in sweep.varies), values, strict=True))}
        row["state"] = state
        row.update({key: status.get(key) for key in ("step", "end_step", "time")})
        trajectory = sweep.run_dir(name) / "trajectory.h5"
        if trajectory.is_file():
            try:
                observed = last_observables(trajectory)
            except OutputError as exc:
                row["error"] = str(exc)
                observed = {}
            for obs, value in observed.items():
                if value.size <= MAX_COLUMNS:  # a profile is too long for a table: sphere plot
                    row.update(_columns(obs, value))
        rows.append(row)
    return rows


def _columns(name: str, value: np.ndarray) -> dict:
    """A scalar as one column, a small tensor as one column per component: name[i][j]."""
    if value.ndim == 0:
        return {name: value.item()}
    return {name + "".join(f"[{i}]" for i in index): value[index].item() for index in np.ndindex(value.shape)}


def write_summary(sweep: Sweep, rows: list[dict]) -> Path:
    header = list(dict.fromkeys(key for row in rows for key in row))
    table = io.StringIO()
    writer = csv.DictWriter(table, header, lineterminator="\n")
    writer.writeheader()
    for row in rows:
        writer.writerow({k: ("" if v is None else _cell(v)) for k, v in row.items()})
    path = sweep.path / "summary.csv"
    try:
        write_text_atomic(path, table.getvalue())
    except OSError as exc:
        raise OutputError(f"{path}: cannot write the summary ({exc})") from None
    return path
