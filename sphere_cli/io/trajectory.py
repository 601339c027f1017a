"""The trajectory file: frames appended on the output schedule, in the H5MD 1.1 layout.

/h5md                          version, author, creator
/particles/trajectory/box      @dimension, @boundary, edges {step, time, value (3,)}, offset
/particles/trajectory/radius   time-independent (N,) [m]
/particles/trajectory/species  time-independent (N,) material id, @materials its names
/particles/trajectory/<field>  {step, time, value} for position, velocity, ...
                               (a scene without particles, a fluid-only one, has the box alone:
                               no radius, mass, species, fields or vertices; its edges are
                               the frames' clock, frame_clock)
/observables/<name>            {step, time, value}: the observables on their own schedule
                               (physics/observe/observables.py); value (samples, ...) holds a scalar,
                               a tensor (3,3) or a profile (layers, ...) per sample
                               (wall series one row per wall, @wall_faces names them)
/fluid/<name>                  {step, time, value}: fluid fields (only when the case has a fluid);
                               @model; on a 3D grid also @origin, @spacing, @shape = (nx, ny, nz),
                               cell-centred values stored as value[frame, k, j, i(, component)]
                               (z slowest, x fastest: the order XDMF/ParaView read)
/parameters                    the case file, the resolved case, the physics hash, dt
/sphere/provenance             versions, threads, host, job id (attributes)
/sphere/xdmf/<series>/<frame>  one HDF5 virtual dataset per frame and per field shown in ParaView:
                               a view of that frame's row of the series, no copy (xdmf.py)
/sphere/xdmf/vertices          0 .. N-1, the particles' vertex cells for XDMF's Polyvertex

The file is opened only while a frame is written, so a crash between frames leaves it whole,
and without HDF5's file lock (`open_as_writer`): a notebook or ParaView holding the file open
must not stop the run. One writer at a time is guaranteed by the run directory's own lock
(rundir.py). A write that fails is logged and retried (WRITE_RETRY_DELAYS) before the run gives up.
"""

from __future__ import annotations

import json
import re
import time
from pathlib import Path

import h5py
import numpy as np

from ..errors import MissingInputError, OutputError, SphereError
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
# Per-frame views of the frame series for the XDMF sidecar: ParaView's XDMF 3 readers do not read
# hyperslabs of a time series, but read a virtual dataset as they read any other
VIEWS = "/sphere/xdmf"
VERTICES = f"{VIEWS}/vertices"  # 0 .. N-1: the Polyvertex connectivity (one vertex cell per particle)
# Seconds waited before each new try of a failed frame or observables write: a file server's
# hiccup or a disk freed by another job in the meantime does not end the run
WRITE_RETRY_DELAYS = (1.0, 2.0, 4.0)
# What a write into an HDF5 file raises when the file system refuses it: OSError, or RuntimeError,
# h5py's report of HDF5's writes failing as it flushes the file at its close (a disk quota, which
# the free-space check cannot see, or a full disk)
HDF5_WRITE_ERRORS = (OSError, RuntimeError)


def open_as_writer(path: Path, mode: str) -> h5py.File:
    """The trajectory opened by the run that writes it (in any mode). HDF5's lock is off: a
    reader's lock (h5py's default) would otherwise make the writer fail; the run directory's lock
    keeps a second sphere out, and the shared lock the run holds on the file (RunDirectory.
    hold_trajectory) any other program opening it to write."""
    return h5py.File(path, mode, locking=False)


def open_to_read(path: Path) -> h5py.File:
    """A file sphere reads (a checkpoint, a trajectory, an input): without HDF5's lock, so that
    the read does not fail where the lock cannot be taken (a file system without locks, NFS
    without its lock service; a file another program holds open for writing), which made a valid
    checkpoint look corrupt and a resume start from an older one. Checkpoints are never written
    in place and the trajectory's writer takes no exclusive lock, so the lock guarded nothing."""
    return h5py.File(path, "r", locking=False)


def not_an_output(path: Path, reason: str, takes: str) -> SphereError:
    """The error for a file given to a command that reads what a run writes (`takes`: what it
    reads), which cannot be read as one, with the reader's `reason`: an HDF5 file's name, a
    damaged output (exit 74, as a checkpoint that fails its verification); any other, a file
    holding nothing usable here (exit 66), saying what it looks like where its name tells."""
    suffix = path.suffix.lower()
    if suffix in (".h5", ".hdf5"):
        return OutputError(f"{path}: {reason}; damaged (cut short, overwritten), or not a file sphere wrote")
    if suffix == ".toml":
        hint = "it looks like a case file, which `sphere validate` checks"
    elif suffix == ".xmf":
        hint = f"it is the XDMF description ParaView opens: give {path.with_suffix('.h5').name} beside it"
    else:
        hint = f"this command reads {takes}"
    return MissingInputError(f"{path}: {reason}; {hint}")


# A unit string of the H5MD units module: factors separated by single spaces, an optional number
# first, then symbols each followed by an optional signed non-zero integer power ("m s-1")
_UNIT_NUMBER = re.compile(r"[0-9]+(\.[0-9]+)?")
_UNIT_SYMBOL = re.compile(r"([A-Za-z]+)(-?[1-9][0-9]*)?")


def set_unit(item, unit: str) -> None:
    """Attach `unit` to a dataset in the notation of H5MD's units module (a programming error
    otherwise: every unit is written through here). Stored as h5py stores a str, which the
    readers in use (MDAnalysis, pyh5md) compare with str keys; H5MD's fixed-length strings would
    read back as bytes there."""
    factors = unit.split(" ")
    if _UNIT_NUMBER.fullmatch(factors[0]):
        factors = factors[1:]
    symbols = [_UNIT_SYMBOL.fullmatch(f) for f in factors]
    if not all(symbols) or len({m.group(1) for m in symbols}) != len(symbols):
        raise ValueError(f"{unit!r} is not an H5MD unit string")
    item.attrs["unit"] = unit


def _time_series(parent: h5py.Group, name: str, shape: tuple, dtype, unit: str) -> None:
    g = parent.create_group(name)
    g.create_dataset("step", shape=(0,), maxshape=(None,), dtype=np.int64, chunks=(256,))
    t = g.create_dataset("time", shape=(0,), maxshape=(None,), dtype=np.float64, chunks=(256,))
    set_unit(t, "s")
    chunk = (max(1, 256 // int(np.prod(shape))), *shape) if shape else (256,)
    v = g.create_dataset("value", shape=(0, *shape), maxshape=(None, *shape), dtype=dtype, chunks=chunk)
    if unit:
        set_unit(v, unit)


def _append(g: h5py.Group, step: int, time: float, value, once: bool = False):
    """One sample at the end of the series `g`; `once`: not if a sample of this step or a later
    one is there (the end sample of a resumed run). Returns the value dataset's low-level id
    (None where nothing was written). Through h5py's low-level calls: a frame or an observables
    sample appends to tens of series, and h5py's high-level lookup, resize and write took 5 x as
    long (about 1 ms a series on this project's machine; a small scene's run spent most of its
    time there)."""
    gid = g.id
    steps, times, values = (h5py.h5d.open(gid, name) for name in (b"step", b"time", b"value"))
    k = steps.shape[0]
    if once and k and _read_row(steps, k - 1)[0] >= step:
        return None
    rows = [
        (series, _row_data(series, row)) for series, row in ((steps, step), (times, time), (values, value))
    ]
    # all three grow before any is written, so a reader sees them of one length most of the time
    for series, data in rows:
        series.set_extent((k + 1, *data.shape))
    for series, data in rows:
        _write_row(series, k, data)
    return values


def _row_space(series, k: int):
    """The file's selection of row k of `series` and the memory space of one row."""
    shape = series.shape[1:]
    file_space = series.get_space()
    file_space.select_hyperslab((k, *(0 for _ in shape)), (1, *shape))
    return file_space, h5py.h5s.create_simple((1, *shape))


def _row_data(series, row) -> np.ndarray:
    """`row` as a contiguous array of the dataset `series`'s type and row shape. Axes of length
    one may be added or left out (a value given as a 1-element array, as h5py's own write took
    it); any other shape is a programming error (ValueError), as it was there."""
    data = np.ascontiguousarray(row, dtype=series.dtype)
    shape = series.shape[1:]
    if data.shape != shape:
        if [n for n in data.shape if n != 1] != [n for n in shape if n != 1]:
            raise ValueError(f"a row of shape {data.shape} for a series of rows {shape}")
        data = data.reshape(shape)
    return data


def _write_row(series, k: int, data: np.ndarray) -> None:
    """Write `data` (_row_data) as row k of the dataset `series` (a DatasetID)."""
    file_space, memory_space = _row_space(series, k)
    series.write(memory_space, file_space, data.reshape(1, *data.shape))


def _read_row(series, k: int) -> np.ndarray:
    file_space, memory_space = _row_space(series, k)
    row = np.empty((1, *series.shape[1:]), dtype=series.dtype)
    series.read(memory_space, file_space, row)
    return row.reshape(-1)


def frame_clock(f: h5py.File) -> h5py.Group:
    """The series whose step and time index the frames: the positions or, in the file of a run
    without particles, the box edges (written with every frame too)."""
    part = f[GROUP]
    return part["position"] if "position" in part else part["box/edges"]


class Trajectory:
    def __init__(self, path: Path, fields: list[str], log=None, particles: bool = True, hold=None):
        """`particles` False: a scene without particles, whose frames hold no particle field.
        `hold`: called before each write to the file once it exists (the run directory's
        hold_trajectory: raises TrajectoryBusy where another program has it open to write)."""
        self.path = path
        self.fields = ["position", *fields] if particles else []
        self.log = log  # where failed tries are reported (the run's log), or None
        self.hold = hold if hold is not None else lambda: None

    def create(self, scene, case_text: str, resolved: dict, physics_hash: str, provenance: dict) -> None:
        state = scene.state
        n = state.particles.count
        try:
            require_free_space(self.path, 64 * n)
            with open_as_writer(self.path, "w") as f:
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
                # time-dependent, one row per frame: the form MDAnalysis reads
                _time_series(box, "edges", (3,), np.float64, "m")
                set_unit(box.create_dataset("offset", data=state.box.lower), "m")
                if n:  # without particles, the box alone
                    set_unit(part.create_dataset("radius", data=state.particles.radius), "m")
                    set_unit(part.create_dataset("mass", data=state.particles.mass), "kg")
                    species = part.create_dataset("species", data=state.particles.material)
                    species.attrs["materials"] = np.array([name.encode() for name in scene.tables.names])
                    f.create_dataset(VERTICES, data=np.arange(n, dtype=np.int64))
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
                params.attrs["dt_bound"] = scene.dt_bound
                prov = f.create_group("sphere/provenance")
                for key, value in provenance.items():
                    prov.attrs[key] = value
        except HDF5_WRITE_ERRORS as exc:
            raise OutputError(f"{self.path}: cannot create the trajectory file ({exc})") from None
        self.hold()

    def _present(self) -> bool:
        """Whether the file is there and not empty (HDF5's append mode would make a missing one
        anew, empty, and fail inside it)."""
        try:
            return self.path.is_file() and self.path.stat().st_size > 0
        except OSError:
            return False

    def _still_there(self) -> None:
        """TrajectoryLost if the file was deleted or emptied while the run writes it (a scratch
        purge, a clean-up)."""
        if not self._present():
            raise TrajectoryLost(f"{self.path}: deleted or emptied while the run writes it")

    def frame_bytes(self, scene, fluid: dict | None = None) -> int:
        """The bytes of one frame's values: the particles' fields and the fluid's (`fluid`:
        its output_fields, where already made)."""
        if fluid is None:
            fluid = scene.fluid.output_fields(scene.state) if scene.fluid is not None else {}
        particles = len(self.fields) * scene.state.particles.pos.nbytes
        return particles + sum(np.asarray(value).nbytes for value, _ in fluid.values())

    def append(self, scene) -> None:
        state = scene.state
        step, time = state.clock.step, state.clock.time
        fluid = scene.fluid.output_fields(state) if scene.fluid is not None else {}
        frame_bytes = self.frame_bytes(scene, fluid)

        def write(retry: bool) -> None:
            require_free_space(self.path, frame_bytes)
            with open_as_writer(self.path, "a") as f:
                if retry:  # a failed try may have left this frame in some series only
                    _cut_frames(f, step - 1)
                part = f[GROUP]
                clock = frame_clock(f)
                frame = clock["step"].shape[0]
                if frame and clock["step"][-1] >= step:
                    return  # this step is already recorded (e.g. the end frame of a resumed run)
                shown = []  # (series, its value dataset) of the frame's views
                for field in self.fields:
                    series = part[field]
                    values = _append(series, step, time, getattr(state.particles, FIELD_SOURCE[field]))
                    shown.append((series.name, values))
                if isinstance(part["box/edges"], h5py.Group):  # a dataset in files before 2026-12
                    _append(part["box/edges"], step, time, state.box.length)
                if fluid:
                    grid = scene.fluid.grid()
                    cells = None if grid is None else tuple(int(n) for n in grid.shape)[::-1]
                    for name, (value, _unit) in fluid.items():
                        values = _append(f["fluid"][name], step, time, _file_order(value, grid))
                        if _has_views(values.shape, cells):
                            shown.append((f"/fluid/{name}", values))
                # a new frame has no views yet (a failed try's were cut above)
                for series, values in shown:
                    _create_view(f, values, frame, xdmf_view(series, frame))

        self._still_there()
        self.hold()
        self._with_retries(f"the frame of step {step}", "cannot append a frame", write)

    def append_observables(self, scene, observables: dict[str, tuple]) -> None:
        """One sample: name -> (value, unit), value a number or an array of fixed shape."""
        clock = scene.state.clock

        def write(retry: bool) -> None:
            require_free_space(self.path, sum(np.asarray(v).nbytes for v, _ in observables.values()))
            with open_as_writer(self.path, "a") as f:
                obs = f["observables"]
                if retry:  # a failed try may have written some of the series
                    _cut_to([obs[name] for name in observables if name in obs], clock.step - 1)
                present = set(obs)
                for name, (value, unit) in observables.items():
                    value = np.asarray(value, dtype=np.float64)
                    if name not in present:
                        _time_series(obs, name, value.shape, np.float64, unit)
                    _append(obs[name], clock.step, clock.time, value, once=True)

        self._still_there()
        self.hold()
        self._with_retries(f"the observables of step {clock.step}", "cannot append observables", write)

    def _with_retries(self, what: str, failure: str, write) -> None:
        """Run write(retry) until it succeeds, logging each failure, up to len(WRITE_RETRY_DELAYS)
        more tries; then raise OutputError."""
        first = None  # the first failure says why; a later try may meet only what it left
        for attempt, delay in enumerate((*WRITE_RETRY_DELAYS, None)):
            try:
                write(attempt > 0)
                if attempt and self.log is not None:
                    self.log.warning("%s written to %s at try %d", what, self.path.name, attempt + 1)
                return
            except HDF5_WRITE_ERRORS as exc:
                said = " ".join(str(exc).split())  # HDF5's messages span lines
                first = first or said
                if delay is None:
                    tries = len(WRITE_RETRY_DELAYS) + 1
                    why = first if said == first else f"{first}; at the last try: {said}"
                    raise OutputError(f"{self.path}: {failure} ({why}; {tries} tries)") from None
                if self.log is not None:
                    self.log.warning(
                        "%s: cannot write %s (%s); trying again in %g s", self.path.name, what, said, delay
                    )
                time.sleep(delay)

    def truncate_after(self, step: int) -> None:
        """Keep what a resume from `step` continues: in every series, the prefix of strictly
        increasing steps up to `step` with step, time and value cut to one length (a kill
        during an append can leave a resized series whose last step was never written, or
        datasets of unequal length); the particle and fluid frames, written together, keep the
        frames they all have. Raises TrajectoryLost when the file is missing or empty,
        OutputError when it is damaged (readers holding it open are no obstacle)."""
        if not self._present():
            raise TrajectoryLost(f"{self.path}: missing or empty")
        self.hold()
        try:
            with open_as_writer(self.path, "a") as f:
                _cut_frames(f, step)
                _cut_to([f["observables"][name] for name in f["observables"]], step)
                # files before 2026-12 have no views
                if VERTICES not in f and "radius" in f[GROUP]:
                    f.create_dataset(VERTICES, data=np.arange(f[GROUP]["radius"].shape[0], dtype=np.int64))
                for k in range(frame_clock(f)["step"].shape[0]):
                    _add_views(f, k)
        except OSError as exc:
            raise OutputError(f"{self.path}: cannot open the trajectory to resume ({exc})") from None
        except Exception as exc:  # a damaged file can fail in any way inside h5py
            raise OutputError(f"{self.path}: damaged trajectory ({type(exc).__name__}: {exc})") from None

    def record_resume(self, step: int, provenance: dict) -> None:
        """Keep the provenance of every resume (host, job id, threads may differ each time)."""
        self.hold()
        try:
            require_free_space(self.path, 0)
            with open_as_writer(self.path, "a") as f:
                resumes = f.require_group("sphere/provenance/resumes")
                group = resumes.create_group(f"{len(resumes):04d}")
                group.attrs["from_step"] = step
                for key, value in provenance.items():
                    group.attrs[key] = value
        except HDF5_WRITE_ERRORS as exc:
            raise OutputError(f"{self.path}: cannot open the trajectory to resume ({exc})") from None


class TrajectoryLost(OutputError):
    """The trajectory file is missing or empty: a resume starts a new one."""


class TrajectoryBusy(OutputError):
    """Another program has the trajectory file open to write: sphere does not write beside it."""


def complete_samples(group: h5py.Group) -> int:
    """The samples of an observable present in each of its step, time and value datasets (a
    run appending while someone reads lengthens them one after the other)."""
    return min(group[name].shape[0] for name in ("step", "time", "value"))


def _valid_prefix(group: h5py.Group, step: int) -> int:
    """How many leading samples have step, time and value, steps strictly increasing, all <= step."""
    n = complete_samples(group)
    steps = group["step"][:n]
    good = steps <= step
    good[1:] &= np.diff(steps) > 0
    return n if good.all() else int(np.argmin(good))


def _cut(group: h5py.Group, keep: int) -> None:
    for name in ("step", "time", "value"):
        if group[name].shape[0] != keep:
            group[name].resize(keep, axis=0)


def _cut_to(groups: list, step: int, together: bool = False) -> None:
    """Cut each series to its valid prefix up to `step`; `together`: then all to the shortest
    (the particle and fluid frames, written together)."""
    for group in groups:
        _cut(group, _valid_prefix(group, step))
    if together:
        common = min((g["step"].shape[0] for g in groups), default=0)
        for group in groups:
            _cut(group, common)


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


def _cut_frames(f: h5py.File, step: int) -> None:
    """Keep the frames up to `step` that every frame series has, and their views only."""
    groups = list(_frame_groups(f))
    _cut_to(groups, step, together=True)
    frames = groups[0]["step"].shape[0]
    if VIEWS in f:
        for series in _view_series(f[VIEWS]):
            for name in [n for n in series if int(n) >= frames]:
                del series[name]


def _view_series(group: h5py.Group):
    """The groups of /sphere/xdmf that hold views (named by frame)."""
    for item in group.values():
        if isinstance(item, h5py.Group):
            if any(isinstance(v, h5py.Dataset) for v in item.values()):
                yield item
            else:
                yield from _view_series(item)


def xdmf_view(series: str, frame: int) -> str:
    """Path of the view of frame `frame` of the series at `series` (its value dataset's group)."""
    return f"{VIEWS}{series}/{frame:08d}"


def _add_views(f: h5py.File, frame: int) -> None:
    """The views of frame `frame` of every frame series ParaView shows: the particle fields and
    the fluid's grid fields (a virtual dataset maps to its row; '.' is this file, wherever it is
    moved)."""
    series = [
        g.name
        for g in f[GROUP].values()
        if isinstance(g, h5py.Group) and "step" in g and g.name != f"{GROUP}/box"
    ]
    if "fluid" in f and "shape" in f["fluid"].attrs:
        cells = tuple(int(n) for n in f["fluid"].attrs["shape"][::-1])
        series += [f"/fluid/{n}" for n, g in f["fluid"].items() if _has_views(g["value"].shape, cells)]
    for path in series:
        view = xdmf_view(path, frame)
        if view not in f:
            _create_view(f, f[path]["value"].id, frame, view)


def _has_views(shape: tuple, cells: tuple | None) -> bool:
    """True for a fluid series of the given (frames, ...) shape that ParaView shows, frame by
    frame: a field on the grid of `cells` (nz, ny, nx; None without a 3D grid)."""
    return cells is not None and tuple(shape[1:4]) == cells


def _create_view(f: h5py.File, values, frame: int, view: str) -> None:
    """The virtual dataset `view` mapping to row `frame` of the dataset `values` (a DatasetID;
    '.' is this file, wherever it is moved), parent groups created as needed. Through h5py's
    low-level calls: its VirtualLayout took half of a small scene's frame."""
    row = values.shape[1:]
    source = values.get_space()
    source.select_hyperslab((frame, *(0 for _ in row)), (1, *row))
    dcpl = h5py.h5p.create(h5py.h5p.DATASET_CREATE)
    dcpl.set_virtual(h5py.h5s.create_simple(row), b".", h5py.h5i.get_name(values), source)
    lcpl = h5py.h5p.create(h5py.h5p.LINK_CREATE)
    lcpl.set_create_intermediate_group(True)
    h5py.h5d.create(f.id, view.encode(), values.get_type(), h5py.h5s.create_simple(row), dcpl=dcpl, lcpl=lcpl)


def _frame_groups(f: h5py.File):
    """The series written with each frame: particle fields, box edges and fluid fields."""
    parents = [f[GROUP], f[GROUP]["box"]] + ([f["fluid"]] if "fluid" in f else [])
    for parent in parents:
        for name in parent:
            item = parent[name]
            if isinstance(item, h5py.Group) and "step" in item:
                yield item
