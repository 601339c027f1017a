"""The trajectory file: frames appended on the output schedule, in the H5MD 1.1 layout.

/h5md                          version, author, creator
/particles/trajectory/box      dimension, boundary, edges
/particles/trajectory/radius   time-independent (N,) [m]
/particles/trajectory/species  time-independent (N,) material id, @materials its names
/particles/trajectory/<field>  {step, time, value} for position, velocity, ...
/observables/<name>            {step, time, value}: the observables on their own schedule
                               (physics/observables.py); value (samples, ...) holds a scalar,
                               a tensor (3,3) or a profile (layers, ...) per sample
                               (wall series one row per wall, @wall_faces names them)
/fluid/<name>                  {step, time, value}: fluid fields (only when the case has a fluid);
                               @model; on a 3D grid also @origin, @spacing, @shape = (nx, ny, nz),
                               cell-centred values stored as value[frame, k, j, i(, component)]
                               (z slowest, x fastest: the order XDMF/ParaView read)
/parameters                    the case file, the resolved case, the physics hash, dt
/sphere/provenance             versions, threads, host, job id (attributes)

The file is opened only while a frame is written, so a crash between frames leaves it whole.
"""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np

from ..errors import OutputError
from .atomic import require_free_space

FIELD_UNITS = {
    "position": "m",
    "velocity": "m s-1",
    "angular_velocity": "s-1",
    "force": "N",
    "torque": "N m",
}
FIELD_SOURCE = {
    "position": "pos",
    "velocity": "vel",
    "angular_velocity": "angvel",
    "force": "force",
    "torque": "torque",
}
GROUP = "/particles/trajectory"


def _time_series(parent: h5py.Group, name: str, shape: tuple, dtype, unit: str) -> None:
    g = parent.create_group(name)
    g.create_dataset("step", shape=(0,), maxshape=(None,), dtype=np.int64, chunks=(256,))
    t = g.create_dataset("time", shape=(0,), maxshape=(None,), dtype=np.float64, chunks=(256,))
    t.attrs["unit"] = "s"
    chunk = (max(1, 256 // int(np.prod(shape))), *shape) if shape else (256,)
    v = g.create_dataset("value", shape=(0, *shape), maxshape=(None, *shape), dtype=dtype, chunks=chunk)
    if unit:
        v.attrs["unit"] = unit


def _append(g: h5py.Group, step: int, time: float, value) -> None:
    k = g["step"].shape[0]
    for name in ("step", "time", "value"):
        g[name].resize(k + 1, axis=0)
    g["step"][k] = step
    g["time"][k] = time
    g["value"][k] = value


class Trajectory:
    def __init__(self, path: Path, fields: list[str]):
        self.path = path
        self.fields = ["position", *fields]

    def create(self, scene, case_text: str, resolved: dict, physics_hash: str, provenance: dict) -> None:
        state = scene.state
        n = state.particles.count
        try:
            require_free_space(self.path, 64 * n)
            with h5py.File(self.path, "w") as f:
                h5 = f.create_group("h5md")
                h5.attrs["version"] = np.array([1, 1], dtype=np.int32)
                h5.create_group("author").attrs["name"] = provenance.get("user", "")
                units = h5.create_group("modules/units")
                units.attrs["version"] = np.array([1, 0], dtype=np.int32)
                units.attrs["system"] = "SI"
                creator = h5.create_group("creator")
                creator.attrs["name"] = "sphere"
                creator.attrs["version"] = provenance.get("sphere_version", "")
                part = f.create_group(GROUP)
                box = part.create_group("box")
                box.attrs["dimension"] = 3
                box.attrs["boundary"] = np.array([b"periodic" if p else b"none" for p in state.box.periodic])
                edges = box.create_dataset("edges", data=state.box.length)
                edges.attrs["unit"] = "m"
                box.create_dataset("offset", data=state.box.lower).attrs["unit"] = "m"
                part.create_dataset("radius", data=state.particles.radius).attrs["unit"] = "m"
                part.create_dataset("mass", data=state.particles.mass).attrs["unit"] = "kg"
                species = part.create_dataset("species", data=state.particles.material)
                species.attrs["materials"] = np.array([name.encode() for name in scene.tables.names])
                for field in self.fields:
                    _time_series(part, field, (n, 3), np.float64, FIELD_UNITS[field])
                obs = f.create_group("observables")  # series are created by their first sample
                if scene.fluid is not None:
                    _create_fluid(f, scene)
                if state.walls is not None:
                    obs.attrs["wall_faces"] = np.array([face.encode() for face in state.walls.faces])
                params = f.create_group("parameters")
                params.attrs["case_toml"] = case_text
                params.attrs["resolved_case"] = json.dumps(resolved)
                params.attrs["physics_hash"] = physics_hash
                params.attrs["dt"] = state.clock.dt
                params.attrs["dt_limit"] = scene.dt_limit
                prov = f.create_group("sphere/provenance")
                for key, value in provenance.items():
                    prov.attrs[key] = value
        except OSError as exc:
            raise OutputError(f"{self.path}: cannot create the trajectory file ({exc})") from None

    def append(self, scene) -> None:
        state = scene.state
        step, time = state.clock.step, state.clock.time
        fluid = scene.fluid.output_fields(state) if scene.fluid is not None else {}
        frame_bytes = len(self.fields) * state.particles.pos.nbytes
        frame_bytes += sum(np.asarray(value).nbytes for value, _ in fluid.values())
        try:
            require_free_space(self.path, frame_bytes)
            with h5py.File(self.path, "a") as f:
                part = f[GROUP]
                if part["position/step"].shape[0] and part["position/step"][-1] >= step:
                    return  # this step is already recorded (e.g. the end frame of a resumed run)
                for field in self.fields:
                    _append(part[field], step, time, getattr(state.particles, FIELD_SOURCE[field]))
                if fluid:
                    grid = scene.fluid.grid()
                    for name, (value, _unit) in fluid.items():
                        _append(f["fluid"][name], step, time, _file_order(value, grid))
        except OSError as exc:
            raise OutputError(f"{self.path}: cannot append a frame ({exc})") from None

    def append_observables(self, scene, observables: dict[str, tuple]) -> None:
        """One sample: name -> (value, unit), value a number or an array of fixed shape."""
        clock = scene.state.clock
        try:
            require_free_space(self.path, sum(np.asarray(v).nbytes for v, _ in observables.values()))
            with h5py.File(self.path, "a") as f:
                obs = f["observables"]
                for name, (value, unit) in observables.items():
                    value = np.asarray(value, dtype=np.float64)
                    if name not in obs:
                        _time_series(obs, name, value.shape, np.float64, unit)
                    group = obs[name]
                    if group["step"].shape[0] and group["step"][-1] >= clock.step:
                        continue  # already recorded (the end sample of a resumed run)
                    _append(group, clock.step, clock.time, value)
        except OSError as exc:
            raise OutputError(f"{self.path}: cannot append observables ({exc})") from None

    def truncate_after(self, step: int) -> None:
        """Keep what a resume from `step` continues: in every series, the prefix of strictly
        increasing steps up to `step` with step, time and value cut to one length (a kill
        during an append can leave a resized series whose last step was never written, or
        datasets of unequal length); the particle and fluid frames, written together, keep the
        frames they all have. Raises TrajectoryLost when the file is missing or empty,
        TrajectoryLocked when another program holds it, OutputError when it is damaged."""
        if not self.path.is_file() or self.path.stat().st_size == 0:
            raise TrajectoryLost(f"{self.path}: missing or empty")
        try:
            with h5py.File(self.path, "a") as f:
                frames = []
                for group in _series_groups(f):
                    keep = _valid_prefix(group, step)
                    if not group.name.startswith("/observables"):
                        frames.append(group)
                    _cut(group, keep)
                common = min((g["step"].shape[0] for g in frames), default=0)
                for group in frames:
                    _cut(group, common)
        except OSError as exc:
            if "unable to lock file" in str(exc):
                raise TrajectoryLocked(
                    f"{self.path}: held open by another program (HDF5 locks the file while it is open); "
                    "close it there and resume again"
                ) from None
            raise OutputError(f"{self.path}: cannot open the trajectory to resume ({exc})") from None
        except Exception as exc:  # a damaged file can fail in any way inside h5py
            raise OutputError(f"{self.path}: damaged trajectory ({type(exc).__name__}: {exc})") from None

    def record_resume(self, step: int, provenance: dict) -> None:
        """Keep the provenance of every resume (host, job id, threads may differ each time)."""
        try:
            require_free_space(self.path, 0)
            with h5py.File(self.path, "a") as f:
                resumes = f.require_group("sphere/provenance/resumes")
                group = resumes.create_group(f"{len(resumes):04d}")
                group.attrs["from_step"] = step
                for key, value in provenance.items():
                    group.attrs[key] = value
        except OSError as exc:
            raise OutputError(f"{self.path}: cannot open the trajectory to resume ({exc})") from None


class TrajectoryLost(OutputError):
    """The trajectory file is missing or empty: a resume starts a new one."""


class TrajectoryLocked(OutputError):
    """Another program holds the trajectory file open; it is not damaged."""


def _valid_prefix(group: h5py.Group, step: int) -> int:
    """How many leading samples have step, time and value, steps strictly increasing, all <= step."""
    n = min(group[name].shape[0] for name in ("step", "time", "value"))
    steps = group["step"][:n]
    good = steps <= step
    good[1:] &= np.diff(steps) > 0
    return n if good.all() else int(np.argmin(good))


def _cut(group: h5py.Group, keep: int) -> None:
    for name in ("step", "time", "value"):
        if group[name].shape[0] != keep:
            group[name].resize(keep, axis=0)


def _create_fluid(f: h5py.File, scene) -> None:
    fluid, state = scene.fluid, scene.state
    group = f.create_group("fluid")
    group.attrs["model"] = fluid.model
    grid = fluid.grid()
    if grid is not None:
        group.attrs["origin"] = np.asarray(grid.origin, dtype=np.float64)
        group.attrs["spacing"] = np.asarray(grid.spacing, dtype=np.float64)
        group.attrs["shape"] = np.asarray(grid.shape, dtype=np.int64)
    for name, (value, unit) in fluid.output_fields(state).items():
        value = _file_order(value, grid)
        _time_series(group, name, value.shape, value.dtype, unit)


def is_grid_field(value: np.ndarray, grid) -> bool:
    return grid is not None and value.ndim in (3, 4) and tuple(value.shape[:3]) == tuple(grid.shape)


def _file_order(value, grid) -> np.ndarray:
    """Grid fields (nx, ny, nz[, 3]) are stored (nz, ny, nx[, 3]); anything else as it is."""
    value = np.asarray(value)
    if is_grid_field(value, grid):
        return np.ascontiguousarray(np.swapaxes(value, 0, 2))
    return value


def _series_groups(f: h5py.File):
    parents = [f[GROUP], f["observables"]] + ([f["fluid"]] if "fluid" in f else [])
    for parent in parents:
        for name in parent:
            item = parent[name]
            if isinstance(item, h5py.Group) and "step" in item:
                yield item
