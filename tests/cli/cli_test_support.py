"""Helpers shared by the CLI tests: a tiny case, running `sphere` in a subprocess or in-process,
and the checks every error message must pass (exit code, key, line or file, no traceback)."""

from __future__ import annotations

import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

from typer.testing import CliRunner

# 20 spheres on a lattice falling onto a floor: 1779 steps with dt = "auto", about a second
# once the kernels are compiled (and cached).
TINY = """\
title = "tiny"

[simulation]
duration = 0.002
dt = "auto"

[domain]
lower = [0.0, 0.0, 0.0]
upper = [0.01, 0.01, 0.02]

[particles]
count = 20
density = 2500.0
radius = { distribution = "uniform", min = 0.0008, max = 0.001 }
placement = { method = "lattice" }

[contact]
model = "linear"
normal_stiffness = 1.0e4

[[walls]]
face = "z-"

[output.frames]
every_steps = 50

[output.checkpoints]
every_steps = 50
keep = 3
"""
TINY_END_STEP = 1779  # round(duration / dt) for the case above (checked against status.json)

# Two spheres read from `spheres.csv` next to the case file.
FROM_FILE = """\
[simulation]
duration = 0.0005

[domain]
upper = [0.01, 0.01, 0.01]

[particles]
density = 2500.0
placement = { method = "file", path = "spheres.csv" }

[contact]
normal_stiffness = 1.0e4
"""
TWO_SPHERES_CSV = "x,y,z,r\n0.003,0.005,0.005,0.001\n0.007,0.005,0.005,0.001\n"


@dataclass
class Result:
    code: int
    stdout: str
    stderr: str


def edit(text: str, old: str, new: str) -> str:
    """Replace the one occurrence of `old` in `text` (fails loudly if the case text drifted)."""
    assert text.count(old) == 1, f"{old!r} occurs {text.count(old)} times in the case"
    return text.replace(old, new)


def line_of(text: str, fragment: str) -> int:
    """1-based number of the first line of `text` that contains `fragment`."""
    for number, line in enumerate(text.splitlines(), start=1):
        if fragment in line:
            return number
    raise AssertionError(f"{fragment!r} not in the case text")


def sphere(*args, cwd: Path | None = None, timeout: float = 300) -> Result:
    """Run the real CLI in a fresh interpreter, as a user would."""
    proc = subprocess.run(
        [sys.executable, "-m", "sphere_cli.cli", *map(str, args)],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
        env={**os.environ, "PYTHONUNBUFFERED": "1"},
    )
    return Result(proc.returncode, proc.stdout, proc.stderr)


def sphere_inproc(*args, cwd: Path | None = None) -> Result:
    """Run the CLI in this process (typer's CliRunner): no interpreter start-up, kernels loaded once."""
    from sphere_cli.cli import app

    previous = Path.cwd()
    if cwd is not None:
        os.chdir(cwd)
    try:
        result = CliRunner().invoke(app, [str(a) for a in args])
    finally:
        os.chdir(previous)
    # An exception other than the SystemExit of typer.Exit is a bug the user would see as a traceback.
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        command = " ".join(map(str, args))
        raise AssertionError(f"sphere {command} raised {result.exception!r}") from result.exception
    return Result(result.exit_code, result.stdout, result.stderr)


def assert_clean_error(result: Result, code: int, *fragments: str) -> None:
    """The exit code is `code`; stderr is a short `sphere: error:` message holding every fragment;
    no traceback anywhere."""
    shown = f"exit {result.code}\nstdout:\n{result.stdout}\nstderr:\n{result.stderr}"
    assert result.code == code, shown
    assert "Traceback" not in result.stderr and "Traceback" not in result.stdout, shown
    for fragment in fragments:
        assert fragment in result.stderr, f"{fragment!r} missing from stderr\n{shown}"
    if code not in (0, 2):  # usage errors are worded by click
        assert "sphere: error: " in result.stderr, shown
        message = result.stderr[result.stderr.index("sphere: error: ") :]
        assert len(message.splitlines()) <= 5, f"error message too long\n{shown}"


# A small laterally periodic scene with a Navier-Stokes fluid (its [fluid] table left open for
# more keys), shared by the fluid and drag bad-input tests.
NAVIER_STOKES_SCENE = """\
[simulation]
duration = 0.0005
dt = "auto"

[domain]
upper = [0.01, 0.01, 0.02]
periodic = [true, true, false]

[particles]
count = 16
density = 2500.0
radius = { distribution = "fixed", value = 0.0005 }
placement = { method = "lattice", region_upper = [0.01, 0.01, 0.008] }

[contact]
normal_stiffness = 1.0e4

[[walls]]
face = "z-"

[fluid]
model = "navier-stokes"
grid = { cells = [4, 4, 8] }
"""
