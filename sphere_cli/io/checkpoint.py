"""Checkpoints: everything a bitwise restart needs, written atomically and checksummed.

RUN_DIR/checkpoints/ckpt-<step>.h5 holds /sphere/state/<module>/<array> (fletcher32 on every
chunk), the clock, the case text and its physics hash, and `complete = 1` written last. The
file is built under a temporary name, fsynced and renamed, so a kill at any moment leaves the
previous checkpoints untouched. The newest K are kept.
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from ..errors import OutputError
from .atomic import publish

FORMAT = 1
NAME = re.compile(r"^ckpt-(\d{12})\.h5$")


@dataclass(frozen=True)
class CheckpointData:
    path: Path
    step: int
    dt: float
    physics_hash: str
    case_text: str
    resolved: dict
    arrays: dict  # module name -> {array name -> ndarray}


def checkpoint_path(directory: Path, step: int) -> Path:
    return directory / f"ckpt-{step:012d}.h5"


def list_checkpoints(directory: Path) -> list[Path]:
    """Checkpoint files, oldest first (by step)."""
    if not directory.is_dir():
        return []
    found = [(int(m.group(1)), p) for p in directory.iterdir() if (m := NAME.match(p.name))]
    return [p for _, p in sorted(found)]


def write_checkpoint(
    directory: Path, scene, case_text: str, resolved: dict, physics_hash: str, keep: int
) -> Path:
    state = scene.state
    final = checkpoint_path(directory, state.clock.step)
    tmp = directory / f".{final.name}.tmp"
    try:
        directory.mkdir(parents=True, exist_ok=True)
        with h5py.File(tmp, "w") as f:
            f.attrs["format"] = FORMAT
            f.attrs["step"] = state.clock.step
            f.attrs["time"] = state.clock.time
            f.attrs["dt"] = state.clock.dt
            f.attrs["physics_hash"] = physics_hash
            f.attrs["case_toml"] = case_text
            f.attrs["resolved_case"] = json.dumps(resolved)
            root = f.create_group("sphere/state")
            for module_name, module in scene.stateful_modules.items():
                group = root.create_group(module_name)
                for name, array in module.prognostic_state(state).items():
                    array = np.asarray(array)
                    if array.ndim == 0 or array.size == 0:
                        group.create_dataset(name, data=array)
                    else:
                        group.create_dataset(name, data=array, fletcher32=True, chunks=True)
            f.attrs["complete"] = 1
        publish(tmp, final)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise OutputError(f"{final}: cannot write checkpoint ({exc})") from None
    for old in list_checkpoints(directory)[:-keep]:
        old.unlink(missing_ok=True)
    return final


def read_checkpoint(path: Path) -> CheckpointData:
    """Read and verify a checkpoint: every chunk's checksum, and the completion mark."""
    try:
        with h5py.File(path, "r") as f:
            if int(f.attrs.get("complete", 0)) != 1 or int(f.attrs.get("format", -1)) != FORMAT:
                raise OutputError(f"{path}: incomplete or unknown checkpoint format")
            arrays = {}
            for module_name, group in f["sphere/state"].items():
                arrays[module_name] = {name: ds[()] for name, ds in group.items()}
            return CheckpointData(
                path=path,
                step=int(f.attrs["step"]),
                dt=float(f.attrs["dt"]),
                physics_hash=str(f.attrs["physics_hash"]),
                case_text=str(f.attrs["case_toml"]),
                resolved=json.loads(f.attrs["resolved_case"]),
                arrays=arrays,
            )
    except OutputError:
        raise
    except (OSError, KeyError, ValueError) as exc:
        raise OutputError(f"{path}: unreadable or corrupt checkpoint ({exc})") from None


def newest_valid_checkpoint(directory: Path, log=None) -> CheckpointData | None:
    for path in reversed(list_checkpoints(directory)):
        try:
            return read_checkpoint(path)
        except OutputError as exc:
            if log is not None:
                log(f"skipping {path.name}: {exc}")
    return None


def remove_stale_temporaries(directory: Path) -> None:
    """Half-written checkpoints left by a kill are never valid; clear them."""
    if directory.is_dir():
        for tmp in directory.glob(".ckpt-*.h5.tmp"):
            tmp.unlink(missing_ok=True)
