"""What every fluid model's table shares: the `[fluid.coupling]` table and the boundary schema of
the bottom and top faces.

Coupling: the DEM takes `steps` steps (or the nearest whole number of steps to `interval`
seconds, the rule of every span of time in a case) with the fluid held, then the fluid advances
over the same time with the particles where they are then. Each model has its own default.

Boundaries: `type = "pressure"` holds the face at pressure + amplitude sin(2 pi t / period +
phase), or at the pressure of a time series read from a file (`series`, linear between its
samples); `type = "no-flow"` lets no fluid through it.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from pydantic import Field, PrivateAttr, model_validator

from .base import Count, Real, Strict

# the solvers' rank_split_cells (Darcy's and Navier-Stokes's [fluid.solver])
RankSplitCells = Annotated[
    Count,
    Field(
        ge=1,
        description=(
            "Split across MPI ranks (mpiexec), each grid level of the solve whose cells give every rank at "
            "least this many is cut into slabs of x planes, one a rank, exchanging the planes beside "
            "them; the others are solved whole on every rank (their messages would cost more than the "
            "work they share). Results are the same bit for bit either way [-]."
        ),
    ),
]


class CouplingConfig(Strict):
    """DEM steps per fluid step, given as a count or as a span of time (not both)."""

    steps: Count | None = Field(
        None,
        ge=1,
        description=(
            "DEM steps per fluid step: the fluid step is steps x dt, and dt must satisfy the "
            "fluid's limits divided by steps [-]."
        ),
    )
    interval: Real | None = Field(
        None,
        gt=0,
        description=(
            "The fluid step as a time instead: round(interval / dt) DEM steps (at least one) per "
            "fluid step; the fluid step must satisfy the fluid's limits, and dt may not exceed "
            "interval [s]."
        ),
    )

    @model_validator(mode="after")
    def _one_way(self):
        if self.steps is not None and self.interval is not None:
            raise ValueError("give either steps or interval, not both")
        return self


class NoFlowBoundary(Strict):
    """A closed face: no fluid crosses it (zero normal gradient of the pressure)."""

    type: Literal["no-flow"] = "no-flow"


class PressureBoundary(Strict):
    """An open face at a prescribed pressure, optionally modulated in time:
    p_b(t) = pressure + amplitude sin(2 pi t / period + phase). Fluid may flow through it."""

    type: Literal["pressure"] = "pressure"
    pressure: Real = Field(0.0, description="Mean pressure on the face [Pa].")
    amplitude: Real = Field(0.0, ge=0, description="Amplitude of the sinusoidal modulation (0 = none) [Pa].")
    period: Real | None = Field(
        None, gt=0, description="Period of the modulation; required when amplitude > 0 [s]."
    )
    phase: Real = Field(0.0, description="Phase of the modulation at t = 0 [rad].")
    series: str | None = Field(
        None,
        description=(
            "A CSV file (relative paths from the case file's folder) of two columns, time in s and "
            "pressure in Pa, one sample a line (a header line and text after # are skipped), times "
            "increasing: the face's pressure is linear between the samples and holds the first "
            "or last value outside them. Exclusive with pressure, amplitude, period and phase."
        ),
    )
    _times: np.ndarray | None = PrivateAttr(None)
    _pressures: np.ndarray | None = PrivateAttr(None)

    @model_validator(mode="after")
    def _period_given(self):
        if self.amplitude > 0 and self.period is None:
            raise ValueError("a modulation (amplitude > 0) needs its period [s]")
        # values, not keys: a resolved case (defaults written out) must validate again
        modulated = (
            self.pressure != 0.0 or self.amplitude != 0.0 or self.period is not None or self.phase != 0.0
        )
        if self.series is not None and modulated:
            raise ValueError(
                "a pressure series replaces pressure, amplitude, period and phase: give one or the other"
            )
        return self

    def value(self, time: float) -> float:
        """The pressure on the face at `time` [s] -> [Pa]."""
        if self.series is not None:
            if self._times is None:
                raise RuntimeError("the pressure series was not read (read_series)")
            return float(np.interp(time, self._times, self._pressures))
        if self.amplitude == 0.0:
            return self.pressure
        return self.pressure + self.amplitude * math.sin(2.0 * math.pi * time / self.period + self.phase)

    def read_series(self, base_dir: Path) -> str | None:
        """Read the `series` file (relative to base_dir); what is wrong with it, or None."""
        path = Path(self.series)
        if not path.is_absolute():
            path = base_dir / path
        try:
            lines = path.read_text(encoding="utf-8-sig").splitlines()
        except FileNotFoundError:
            return f"file not found ({path})"
        except (OSError, ValueError) as exc:
            return f"{path}: not a readable text file ({exc})"
        rows, header_allowed = [], True
        for number, line in enumerate(lines, start=1):
            fields = [f.strip() for f in line.split("#")[0].split(",")]
            if fields == [""]:
                continue
            try:
                if len(fields) != 2:
                    raise ValueError
                rows.append((float(fields[0]), float(fields[1])))
            except ValueError:
                if header_allowed:  # the first line not blank or a comment may name the columns
                    header_allowed = False
                    continue
                return (
                    f"{path}:{number}: expected two numbers, time [s] and pressure [Pa], got {line.strip()!r}"
                )
            header_allowed = False
        data = np.array(rows, dtype=np.float64).reshape(-1, 2)
        if len(data) < 1:
            return f"{path}: no samples (two numbers a line: time [s], pressure [Pa])"
        if not np.isfinite(data).all():
            return f"{path}: a time or pressure is not finite"
        if np.any(np.diff(data[:, 0]) <= 0):
            return f"{path}: the times must increase from one line to the next"
        self._times, self._pressures = data[:, 0].copy(), data[:, 1].copy()
        return None


# case keys of earlier versions -> the key that replaces them (an old key is refused by name)
RENAMED = {
    ("fluid", "update_every"): "fluid.coupling.steps",
    ("fluid", "coupling_interval"): "fluid.coupling.interval",
    ("fluid", "coupling", "ndem"): "fluid.coupling.steps",
    ("fluid", "coupling", "fluid_dt"): "fluid.coupling.interval",
    ("fluid", "top", "condition"): "fluid.top.type",
    ("fluid", "bottom", "condition"): "fluid.bottom.type",
    ("fluid", "top", "frequency"): "fluid.top.period (= 1/frequency)",
    ("fluid", "bottom", "frequency"): "fluid.bottom.period (= 1/frequency)",
    ("fluid", "beta"): "fluid.old_pressure_weight",
    ("fluid", "phi_max"): "fluid.packed_solid_fraction",
}
