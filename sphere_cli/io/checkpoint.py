"""Checkpoints: everything a bitwise restart needs, written atomically and checksummed.

RUN_DIR/checkpoints/ckpt-<step>.h5 holds /sphere/state/<module>/<array> (fletcher32 on every
chunk), the clock, the case text and its physics hash, `complete = 1`, and `digest`: a SHA-256
of every other attribute and every dataset (name, dtype, shape and bytes), so that a changed
`step`, `dt` or scalar, which no chunk checksum covers, is found too. The file is built under a
temporary name, fsynced and renamed, so a kill at any moment leaves the previous checkpoints
untouched. The newest K are kept. Reading verifies everything before anything is trusted; any
failure to read makes the file invalid (the caller falls back to an older one).
"""

from __future__ import annotations

import hashlib
import io
import json
import re
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from ..errors import OutputError, ResumeRefused
from .atomic import publish
from .trajectory import open_to_read

# 2: with the digest; 3: one fluid vocabulary, no springs without friction; 4: the Navier-Stokes
# velocity on the faces of a staggered grid (3 held it at the cell centres); 5: the self-induced
# velocity of each particle with the Navier-Stokes drag
FORMAT = 5
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
    image = _checkpoint_image(scene, case_text, resolved, physics_hash)
    try:
        directory.mkdir(parents=True, exist_ok=True)
        write_file(tmp, image)
        publish(tmp, final)
    except OSError as exc:
        tmp.unlink(missing_ok=True)
        raise OutputError(f"{final}: cannot write checkpoint ({exc.strerror or exc})") from None
    for old in list_checkpoints(directory)[:-keep]:
        old.unlink(missing_ok=True)
    return final


def _checkpoint_image(scene, case_text: str, resolved: dict, physics_hash: str) -> bytes:
    """The checkpoint file's bytes, built in memory: HDF5 never writes to the disk itself, so a
    full disk is one clean OSError of the plain write (inside HDF5 it ends in a crash)."""
    state = scene.state
    buffer = io.BytesIO()
    with h5py.File(buffer, "w") as f:
        f.attrs["format"] = FORMAT
        f.attrs["step"] = state.clock.step
        f.attrs["time"] = state.clock.time
        f.attrs["dt"] = state.clock.dt
        f.attrs["physics_hash"] = physics_hash
        f.attrs["case_toml"] = case_text
        f.attrs["resolved_case"] = json.dumps(resolved)
        root = f.create_group("sphere/state")
        for module_name, module in scene.step.stateful.items():
            group = root.create_group(module_name)
            for name, array in module.prognostic_state(state).items():
                array = np.asarray(array)
                if array.ndim == 0 or array.size == 0:
                    group.create_dataset(name, data=array)
                else:
                    group.create_dataset(name, data=array, fletcher32=True, chunks=True)
        f.attrs["complete"] = 1
    with h5py.File(buffer, "r+") as f:
        f.attrs["digest"] = _digest(f)
    return buffer.getvalue()


def write_file(path: Path, data: bytes) -> None:
    with open(path, "wb") as out:
        out.write(data)


def read_checkpoint(path: Path) -> CheckpointData:
    """Read and verify a checkpoint: the completion mark, the format, the digest of every
    attribute and dataset, and (while reading) every chunk's checksum."""
    try:
        with open_to_read(path) as f:
            if int(f.attrs.get("complete", 0)) != 1:
                raise OutputError(f"{path}: incomplete checkpoint")
            if int(f.attrs.get("format", -1)) != FORMAT:
                raise ResumeRefused(_format_refusal(path, f))
            if str(f.attrs.get("digest", "")) != _digest(f):
                raise OutputError(f"{path}: digest mismatch (an attribute or dataset was changed)")
            step = int(f.attrs["step"])
            if NAME.match(path.name) and int(NAME.match(path.name).group(1)) != step:
                raise OutputError(f"{path}: holds step {step}, not the step of its name")
            arrays = {}
            for module_name, group in f["sphere/state"].items():
                arrays[module_name] = {name: ds[()] for name, ds in group.items()}
            return CheckpointData(
                path=path,
                step=step,
                dt=float(f.attrs["dt"]),
                physics_hash=str(f.attrs["physics_hash"]),
                case_text=str(f.attrs["case_toml"]),
                resolved=json.loads(f.attrs["resolved_case"]),
                arrays=arrays,
            )
    except (OutputError, ResumeRefused):
        raise
    except Exception as exc:  # a damaged file can fail in any way inside h5py
        raise OutputError(f"{path}: unreadable or corrupt checkpoint ({type(exc).__name__}: {exc})") from None


def _digest(f: h5py.File) -> str:
    """SHA-256 of every attribute (but the digest) and every dataset, in name order."""
    sha = hashlib.sha256()

    def add(kind: str, name: str, value) -> None:
        if isinstance(value, bytes | str):
            data, form = (value.encode() if isinstance(value, str) else value), "str"
        else:
            array = np.ascontiguousarray(value)
            data, form = array.tobytes(), f"{array.dtype.str}{array.shape}"
        sha.update(f"{kind}:{name}:{form}:{len(data)}:".encode())
        sha.update(data)

    def attributes(name: str, obj) -> None:
        for key in sorted(obj.attrs):
            if not (name == "/" and key == "digest"):
                add("attr", f"{name}@{key}", obj.attrs[key])

    names: list[str] = []
    f.visit(names.append)
    attributes("/", f)
    for name in sorted(names):
        obj = f[name]
        attributes(name, obj)
        if isinstance(obj, h5py.Dataset):
            add("data", name, obj[()])
    return sha.hexdigest()


def _format_refusal(path: Path, f) -> str:
    """Why a checkpoint of another format cannot be resumed (a complete, older checkpoint is not
    damaged: it must be refused, not skipped for an even older one of the same run)."""
    found = f.attrs.get("format")
    text = f"{path}: checkpoint format {found}, this version reads format {FORMAT} only"
    fluid = (
        "sphere/state/fluid" in f
        and "v" in f["sphere/state/fluid"]
        and "v_face" not in f["sphere/state/fluid"]
    )
    if fluid:
        text += (
            "; it holds a Navier-Stokes fluid on the collocated grid of earlier versions (velocity at the "
            "cell centres), which the staggered grid of this version (velocity on the cell faces) cannot "
            "continue from"
        )
    return (
        text
        + ". Start the run again from its case file (sphere run), or resume it with the version that wrote it"
    )


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
