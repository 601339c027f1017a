"""Summaries of any output: a run directory, a trajectory file or a checkpoint file."""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import h5py
import numpy as np

from ..errors import MissingInputError, OutputError, ResumeRefused
from ..physics.fluid_plugin import MOVING_GRID_SPACING
from .checkpoint import list_checkpoints, read_checkpoint
from .rundir import RunDirectory
from .trajectory import complete_samples, frame_clock, not_an_output, open_to_read


def summarize(path: Path) -> dict:
    if not path.exists():
        raise MissingInputError(f"{path}: no such file or directory")
    if path.is_dir():
        return _run_directory(RunDirectory(path))
    try:
        with open_to_read(path) as f:
            is_trajectory = "h5md" in f
    except Exception as exc:  # a damaged file can fail in any way inside h5py
        reason = f"not a readable HDF5 file ({exc})"
        raise not_an_output(path, reason, "a run directory, a trajectory.h5 or a checkpoint") from None
    return _trajectory(path) if is_trajectory else _checkpoint(path)


def _run_directory(rundir: RunDirectory) -> dict:
    if not rundir.is_run():
        if (rundir.path / "sweep.json").is_file():
            raise MissingInputError(
                f"{rundir.path}: a sweep's folder, not a run directory: `sphere sweep-summary {rundir.path}` "
                "tabulates its members; each member's run is in its runs/ folder"
            )
        raise MissingInputError(rundir.why_not_run())
    out = {"kind": "run directory", "path": str(rundir.path)}
    if rundir.status_path.is_file():
        try:
            out["status"] = json.loads(rundir.status_path.read_text(encoding="utf-8"))
        except (OSError, ValueError) as exc:
            out["status"] = {"error": f"{rundir.status_path}: unreadable ({exc})"}
        status = out["status"]
        if status.get("state") in ("starting", "running") and rundir.writer_gone():
            status["writer"] = (
                "gone: no process holds the run (killed, or its machine went down); `sphere resume "
                f"{rundir.path}` continues it from its newest checkpoint"
            )
    if rundir.trajectory_path.is_file():
        try:
            out["trajectory"] = _trajectory(rundir.trajectory_path)
        except OutputError as exc:
            out["trajectory"] = {"error": str(exc)}
    out["checkpoints"] = [_checkpoint_entry(p) for p in list_checkpoints(rundir.checkpoints)]
    return out


def _checkpoint_entry(path: Path) -> dict:
    try:
        ck = read_checkpoint(path)
        return {"file": path.name, "step": ck.step, "time": ck.step * ck.dt, "valid": True}
    except (OutputError, ResumeRefused) as exc:  # damaged, or of another format
        return {"file": path.name, "valid": False, "error": str(exc)}


# A running run may be appending a frame while the trajectory is read: its metadata can then be
# caught half-written, and reading again a moment later finds the frame complete
READ_RETRY_DELAYS = (0.2, 0.5, 1.0)


def _retrying(read, path: Path):
    for delay in READ_RETRY_DELAYS:
        try:
            return read(path)
        except OutputError:
            time.sleep(delay)
    return read(path)


def _trajectory(path: Path) -> dict:
    return _retrying(_read_trajectory, path)


def last_observables(path: Path) -> dict[str, np.ndarray]:
    """The last sample of every observable that has one, as stored (full precision), from a
    trajectory that may be growing."""
    return _retrying(_read_last_observables, path)


def _read_last_observables(path: Path) -> dict[str, np.ndarray]:
    try:
        with open_to_read(path) as f:
            return {name: g["value"][-1] for name, g in f["observables"].items() if g["value"].shape[0]}
    except Exception as exc:  # a damaged file can fail in any way inside h5py
        raise OutputError(f"{path}: not a readable sphere trajectory ({type(exc).__name__}: {exc})") from None


def _read_trajectory(path: Path) -> dict:
    try:
        with open_to_read(path) as f:
            params = f["parameters"].attrs
            resolved = json.loads(params["resolved_case"])
            part = f["particles/trajectory"]
            clock = frame_clock(f)
            steps = clock["step"][...]
            times = clock["time"][...]
            obs = {
                name: _last_sample(group)
                for name, group in f["observables"].items()
                if complete_samples(group)
            }
            steady = {}
            for name, group in f["observables"].items():
                if group["value"].ndim == 1:
                    n = complete_samples(group)
                    estimate = steady_estimate(group["time"][:n], group["value"][:n])
                    if estimate is not None:
                        steady[name] = _describe_steady(estimate, group["value"].attrs.get("unit", ""))
            return {
                "kind": "trajectory",
                "path": str(path),
                "title": resolved.get("title", ""),
                "particles": int(part["radius"].shape[0]) if "radius" in part else 0,
                "frames": int(steps.size),
                "first_time": float(times[0]) if times.size else None,
                "last_step": int(steps[-1]) if steps.size else None,
                "last_time": float(times[-1]) if times.size else None,
                "dt": float(params["dt"]),
                "dt_limit": float(params["dt_limit"]),
                "dt_bound": float(params.get("dt_bound", float("nan"))),  # written since 2026-12
                "contact_model": (resolved.get("contact") or {}).get("model"),
                "walls": [w["face"] for w in resolved.get("walls", [])],
                "periodic": resolved["domain"]["periodic"],
                "fluid": _fluid(f),
                "last_observables": obs,
                "steady_state": steady,
                "provenance": dict(f["sphere/provenance"].attrs.items()),
            }
    except Exception as exc:  # a damaged file can fail in any way inside h5py
        raise OutputError(f"{path}: not a readable sphere trajectory ({type(exc).__name__}: {exc})") from None


def _fluid(f: h5py.File) -> dict | None:
    """The fluid model, its grid and the range of each field in the last frame."""
    if "fluid" not in f:
        return None
    group = f["fluid"]
    out = {"model": str(group.attrs["model"])}
    if "shape" in group.attrs:
        out["grid_cells"] = [int(c) for c in group.attrs["shape"]]
        out["cell_size"] = [float(c) for c in group.attrs["spacing"]]
        moving = group.get(MOVING_GRID_SPACING)
        if moving is not None and moving["value"].shape[0]:
            # a grid following the top wall: its cells and height in the last frame
            out["cell_size"] = [float(c) for c in moving["value"][-1]]
            out["grid_height"] = out["grid_cells"][2] * out["cell_size"][2]
    for name, series in group.items():
        values = series["value"]
        unit = values.attrs.get("unit", "")
        if values.shape[0]:
            last = values[-1]
            out[name] = f"min {last.min():.6g}, max {last.max():.6g} {unit}".rstrip()
    return out


STEADY_BATCHES = 8  # batch means of the latter half of a series
STEADY_MIN_SAMPLES = 4 * STEADY_BATCHES


def steady_estimate(times: np.ndarray, values: np.ndarray) -> dict | None:
    """Whether a scalar time series has settled, and at what: over the latter half of its
    samples (the last STEADY_BATCHES x k), the mean and its standard error from the spread of
    STEADY_BATCHES batch means (which holds for samples correlated over less than a batch), and
    the drift: the slope of a straight line through the batch means over its standard error (a
    Student t of STEADY_BATCHES - 2 degrees of freedom; |drift| above about 3: still changing).
    None with fewer than STEADY_MIN_SAMPLES finite samples."""
    values = np.asarray(values, dtype=np.float64)
    if values.size < STEADY_MIN_SAMPLES or not np.isfinite(values).all():
        return None
    per_batch = values.size // 2 // STEADY_BATCHES
    tail = values[-per_batch * STEADY_BATCHES :]
    batches = tail.reshape(STEADY_BATCHES, per_batch).mean(axis=1)
    x = np.arange(STEADY_BATCHES) - 0.5 * (STEADY_BATCHES - 1)
    slope = float(x @ batches / (x @ x))
    residual = batches - batches.mean() - slope * x
    slope_error = math.sqrt(float(residual @ residual) / (STEADY_BATCHES - 2) / float(x @ x))
    if slope_error > 0.0:
        drift = slope / slope_error
    else:
        drift = 0.0 if slope == 0.0 else math.copysign(math.inf, slope)
    return {
        "mean": float(batches.mean()),
        "error": float(batches.std(ddof=1) / math.sqrt(STEADY_BATCHES)),
        "from_time": float(times[-tail.size]),
        "to_time": float(times[-1]),
        "drift_sigma": drift,
    }


def _describe_steady(e: dict, unit: str) -> str:
    unit = f" {unit}" if unit and unit != "1" else ""
    return (
        f"{e['mean']:.6g} +- {e['error']:.2g}{unit} over t = {e['from_time']:.6g} .. {e['to_time']:.6g} s "
        f"({STEADY_BATCHES} batch means of the last half), drift {e['drift_sigma']:+.1f} sigma"
    )


def _last_sample(group: h5py.Group):
    """The last sample of an observable: a number, a small tensor as nested lists, or for a
    profile its shape, unit and range (the whole series: `sphere plot`, or the file itself)."""
    samples = complete_samples(group)
    value = group["value"][samples - 1]
    unit = group["value"].attrs.get("unit", "")
    if value.ndim == 0:
        return value.item()
    if value.size <= 24:  # a tensor, or one row per wall
        return np.vectorize(lambda x: float(f"{x:.6g}"), otypes=[float])(value).tolist()
    return (
        f"{value.shape[0]} layers x {value.shape[1:] or 'scalar'}, {samples} samples, "
        f"last from {value.min():.4g} to {value.max():.4g}" + (f" {unit}" if unit else "")
    )


def _checkpoint(path: Path) -> dict:
    ck = read_checkpoint(path)
    return {
        "kind": "checkpoint",
        "path": str(path),
        "valid": True,
        "step": ck.step,
        "time": ck.step * ck.dt,
        "dt": ck.dt,
        "particles": int(ck.arrays["particles"]["pos"].shape[0]) if "particles" in ck.arrays else 0,
        "modules": sorted(ck.arrays),
        "physics_hash": ck.physics_hash,
    }


def render(summary: dict, indent: str = "") -> str:
    lines = []
    for key, value in summary.items():
        if isinstance(value, dict):
            lines.append(f"{indent}{key}:")
            lines.append(render(value, indent + "  "))
        elif isinstance(value, list) and value and isinstance(value[0], dict):
            lines.append(f"{indent}{key}:")
            for item in value:
                lines.append(indent + "  - " + ", ".join(f"{k}={v}" for k, v in item.items()))
        else:
            lines.append(f"{indent}{key}: {value}")
    return "\n".join(lines)
