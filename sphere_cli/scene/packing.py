"""Initial particle positions: jittered lattice, random non-overlapping insertion, or a file."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..config.load import case_error
from ..config.memory import CELLS_PER_PARTICLE
from ..config.schema import FilePlacement, LatticePlacement, RandomPlacement
from ..errors import CaseError, MissingInputError
from ..kernels.packing import insert_random


def _region(placement, case):
    lower = np.array(placement.region_lower or case.domain.lower, dtype=np.float64)
    upper = np.array(placement.region_upper or case.domain.upper, dtype=np.float64)
    return lower, upper


def lattice_sites(placement: LatticePlacement, case, radius) -> tuple[np.ndarray, float]:
    """(sites along x, y, z; spacing [m]) of the lattice for these radii, refused (CaseError on
    particles.count) when it cannot hold them all. Also run by `sphere validate`."""
    rmax = radius.max()
    spacing = placement.spacing * 2.0 * rmax
    lower, upper = _region(placement, case)
    # counted in floats and held to the particles' number per axis (more are never used: the
    # sites fill x first, then y, then z), so that a tiny spacing cannot overflow int64
    along = np.floor((upper - lower - 2.0 * rmax) / spacing + 1e-9) + 1.0
    sites = np.minimum(along, float(radius.size)).astype(np.int64)
    capacity = float(np.prod(along))
    if capacity < radius.size:
        raise case_error(
            case,
            ("particles", "count"),
            f"the lattice (particles.placement) holds only {capacity:.0f} sites ({sites[0]} x {sites[1]} x "
            f"{sites[2]} at spacing {spacing:g} m); enlarge the box or region, lower "
            "particles.placement.spacing, or use fewer particles",
        )
    return sites, spacing


def lattice_positions(placement: LatticePlacement, case, radius, rng) -> np.ndarray:
    """Simple-cubic sites filled bottom layer first (z, then y, then x slowest)."""
    rmax = radius.max()
    sites, spacing = lattice_sites(placement, case, radius)
    lower, upper = _region(placement, case)
    first = lower + rmax
    k = np.arange(radius.size)
    ix = k % sites[0]
    iy = (k // sites[0]) % sites[1]
    iz = k // (sites[0] * sites[1])
    pos = first + spacing * np.stack([ix, iy, iz], axis=1)
    gap = spacing - 2.0 * rmax
    pos += placement.jitter * 0.5 * gap * rng.uniform(-1.0, 1.0, size=pos.shape)
    return np.clip(pos, lower + radius[:, None], upper - radius[:, None])


def random_positions(placement: RandomPlacement, case, radius, rng) -> np.ndarray:
    lower, upper = _region(placement, case)
    # a periodic axis the region fills is drawn whole: spheres may straddle its boundary, so the
    # packing has no seam (elsewhere each centre keeps a radius from the region's faces)
    wrap = (
        np.asarray(case.domain.periodic, dtype=bool)
        & (lower == np.asarray(case.domain.lower))
        & (upper == np.asarray(case.domain.upper))
    )
    inset = np.where(wrap, 0.0, 1.0) * radius[:, None, None]
    lo = lower + inset
    hi = upper - inset
    cand = lo + (hi - lo) * rng.random((radius.size, placement.max_attempts, 3))
    # cells of one largest diameter, coarser where that would be more than a few per particle
    # (uniform candidates fill them evenly, so a coarser cell only costs a few more checks)
    cell = max(2.0 * radius.max(), (np.prod(upper - lower) / (CELLS_PER_PARTICLE * radius.size)) ** (1 / 3))
    ncell = np.maximum(np.floor((upper - lower) / cell).astype(np.int64), 1)
    pos = np.zeros((radius.size, 3))
    # large spheres first: they are the hardest to fit
    order = np.argsort(-radius, kind="stable")
    placed = insert_random(
        radius[order], cand[order], lower, cell, ncell, upper - lower, wrap.astype(np.uint8), pos
    )
    if placed < radius.size:
        raise case_error(
            case,
            ("particles", "placement"),
            f"random insertion placed only {placed} of {radius.size} particles after "
            f"{placement.max_attempts} attempts each; enlarge the region, use fewer particles, "
            'or use method = "lattice"',
        )
    out = np.empty_like(pos)
    out[order] = pos
    return out


@dataclass
class ParticleFile:
    """What a placement file gives: positions, and each of the optional columns or None."""

    pos: np.ndarray  # (N,3) [m]
    radius: np.ndarray | None = None  # (N,) [m]
    velocity: np.ndarray | None = None  # (N,3) [m/s]
    angular_velocity: np.ndarray | None = None  # (N,3) [rad/s]
    material: np.ndarray | None = None  # (N,) str: names from particles.material
    group: np.ndarray | None = None  # (N,) str: names of particles.groups, "" for none
    fixed: np.ndarray | None = None  # (N,) bool


VECTORS = {"velocity": ("vx", "vy", "vz"), "angular_velocity": ("wx", "wy", "wz")}
# the columns a CSV particle file may have (any other is refused: its data would be dropped)
CSV_COLUMNS = ("x", "y", "z", "r", "vx", "vy", "vz", "wx", "wy", "wz", "material", "group", "fixed")
# the datasets an HDF5 particle file may have at its root (likewise; groups and attributes are
# not read, and may hold anything)
HDF5_DATASETS = ("position", "radius", "velocity", "angular_velocity", "material", "group", "fixed")
FLAGS = {"1": True, "true": True, "yes": True, "0": False, "false": False, "no": False, "": False}


# particles whose candidate pairs are found at once by worst_overlap_of (bounds its memory)
OVERLAP_BLOCK = 1 << 18


def worst_overlap_of(pos, radius, lower, upper, periodic) -> tuple[int, int, float]:
    """The pair with the largest overlap relative to the smaller radius, (i, j, overlap / min(r_i,
    r_j)), (-1, -1, 0.0) when nothing touches: kernels/neighbors.py worst_overlap without a
    neighbour list, in numpy (no kernel to compile: `sphere validate`). Candidates: the spheres
    in the same or an adjacent cell of a grid of cells at least the largest diameter wide,
    periodic where the box is (distances by the minimum image there): a pair in one cell once
    (j > i), a pair of cells once, from the cell whose neighbour lies ahead of it (half of the
    26 directions)."""
    n = radius.size
    if n < 2:
        return -1, -1, 0.0
    length = upper - lower
    ncell = np.maximum((length // (2.0 * float(radius.max()))).astype(np.int64), 1)
    cell = np.floor((pos - lower) / length * ncell).astype(np.int64)
    cell = np.where(periodic.astype(bool), cell % ncell, np.clip(cell, 0, ncell - 1))
    key = (cell[:, 0] * ncell[1] + cell[:, 1]) * ncell[2] + cell[:, 2]
    order = np.argsort(key, kind="stable")
    sorted_key = key[order]
    best = (-1, -1, 0.0)
    every = [(a, b, c) for a in (-1, 0, 1) for b in (-1, 0, 1) for c in (-1, 0, 1)]
    offsets = np.array([o for o in every if o >= (0, 0, 0)])  # (0, 0, 0) first, then 13 ahead
    for first in range(0, n, OVERLAP_BLOCK):
        rows = order[first : first + OVERLAP_BLOCK]  # by cell: the searches below run in order
        for offset in offsets:
            near = cell[rows] + offset
            inside = np.ones(rows.size, dtype=bool)
            for a in range(3):
                if periodic[a]:
                    near[:, a] %= ncell[a]
                else:
                    inside &= (near[:, a] >= 0) & (near[:, a] < ncell[a])
            near_key = (near[:, 0] * ncell[1] + near[:, 1]) * ncell[2] + near[:, 2]
            start = np.searchsorted(sorted_key, near_key, "left")
            count = np.where(inside, np.searchsorted(sorted_key, near_key, "right") - start, 0)
            i = np.repeat(rows, count)
            within = np.arange(i.size) - np.repeat(np.cumsum(count) - count, count)
            j = order[np.repeat(start, count) + within]
            # in its own cell a pair once; a periodic axis of one or two cells wraps a neighbour
            # onto the cell itself or one seen already: a pair may come twice, never i with i
            pair = j > i if not offset.any() else j != i
            i, j = i[pair], j[pair]
            if not i.size:
                continue
            d = pos[j] - pos[i]
            d -= np.where(periodic.astype(bool), length * np.round(d / length), 0.0)
            overlap = (radius[i] + radius[j] - np.sqrt((d * d).sum(axis=1))) / np.minimum(
                radius[i], radius[j]
            )
            k = int(np.argmax(overlap))
            if overlap[k] > best[2]:
                best = (int(min(i[k], j[k])), int(max(i[k], j[k])), float(overlap[k]))
    return best


def particle_file_path(placement: FilePlacement, base_dir: Path) -> Path:
    path = Path(placement.path)
    return path if path.is_absolute() else base_dir / path


def placed_count(placement: FilePlacement, base_dir: Path) -> int | None:
    """How many particles a placement file holds, counted without reading them (the CSV's data
    lines, the HDF5 file's rows of 'position'), to size the run's threads before the scene is
    built; None where it cannot tell (the build then reports what is wrong with the file)."""
    path = particle_file_path(placement, base_dir)
    try:
        if path.suffix.lower() in (".h5", ".hdf5"):
            from ..io.trajectory import open_to_read

            with open_to_read(path) as f:
                return int(f["position"].shape[0])
        with path.open(encoding="utf-8-sig") as lines:
            return max(0, sum(1 for line in lines if _content(line).strip()) - 1)  # the header
    except (OSError, ValueError, KeyError, TypeError, IndexError):
        return None


def read_particle_file(placement: FilePlacement, base_dir: Path) -> ParticleFile:
    path = particle_file_path(placement, base_dir)
    if not path.is_file():
        raise case_error(
            placement, ("particles", "placement", "path"), f"file not found ({path})", MissingInputError
        )
    if path.suffix.lower() in (".h5", ".hdf5"):
        return _checked(path, _read_hdf5(path))
    return _checked(path, _read_csv(path))


def _content(line: str) -> str:
    """A CSV line without its comment (text after #): blank, it holds no row (placed_count
    counts the rows _read_csv reads)."""
    return line.split("#")[0]


def _read_csv(path: Path) -> ParticleFile:
    """Comma-separated, a header of column names first; blank lines and text after # are skipped.
    A field that is not what its column needs is refused by its line and column."""
    try:
        text = path.read_text(encoding="utf-8-sig")  # Excel's "CSV UTF-8" begins with a byte-order mark
    except (ValueError, OSError) as exc:  # UnicodeDecodeError is a ValueError
        raise CaseError(f"{path}: not a readable CSV particle file ({exc})") from None
    rows = [
        (number, [field.strip() for field in _content(line).split(",")])
        for number, line in enumerate(text.splitlines(), start=1)
        if _content(line).strip()
    ]
    names = rows[0][1] if rows else []
    for name in names:
        if names.count(name) > 1 or name == "":
            raise CaseError(f"{path}:{rows[0][0]}: the header names {name!r} more than once or not at all")
    if not {"x", "y", "z"} <= set(names):
        raise CaseError(
            f"{path}: the CSV header must name columns x, y, z (and optionally r, vx, vy, vz, wx, wy, wz, "
            f"material, group, fixed); got {tuple(names)}"
        )
    for name in names:  # a column read by no one (radius for r, an id) would drop its data silently
        if name not in CSV_COLUMNS:
            hint = " (the radius column is r)" if name.lower() in ("radius", "radii", "rad") else ""
            raise CaseError(
                f"{path}:{rows[0][0]}: unknown column {name!r}{hint}; the columns are x, y, z and "
                "optionally r, vx, vy, vz, wx, wy, wz, material, group, fixed"
            )
    for triple in VECTORS.values():
        given = [c for c in triple if c in names]
        if 0 < len(given) < 3:
            raise CaseError(
                f"{path}:{rows[0][0]}: columns {', '.join(given)} without the rest of {', '.join(triple)}"
            )
    rows = rows[1:]
    for number, fields in rows:
        if len(fields) != len(names):
            raise CaseError(f"{path}:{number}: {len(fields)} fields, but the header names {len(names)}")
    columns = {}
    for c, name in enumerate(names):
        if name in ("material", "group"):
            columns[name] = np.array([f[c] for _, f in rows], dtype=str)
        else:
            values = [_field(path, number, c, name, f[c]) for number, f in rows]
            columns[name] = np.array(values, dtype=bool if name == "fixed" else float)
    return ParticleFile(
        pos=np.stack([columns[a] for a in "xyz"], axis=1).reshape(-1, 3),
        radius=columns.get("r"),
        **{key: _vector(columns, triple) for key, triple in VECTORS.items()},
        material=columns.get("material"),
        group=columns.get("group"),
        fixed=columns.get("fixed"),
    )


def _vector(columns: dict, triple) -> np.ndarray | None:
    """The (N,3) vector of these three columns, or None if the file has not all three."""
    return np.stack([columns[c] for c in triple], axis=1) if set(triple) <= set(columns) else None


def _field(path: Path, line: int, column: int, name: str, field: str):
    """The field as its column needs it: a flag for `fixed`, a finite number for the others."""
    where = f"{path}:{line}: column {name} (column {column + 1}) = {field!r}"
    if name == "fixed":
        if field.lower() not in FLAGS:
            raise CaseError(f"{where}: expected 1 or 0 (true or false)")
        return FLAGS[field.lower()]
    try:
        value = float(field)
    except ValueError:
        raise CaseError(f"{where}: not a number") from None
    if not math.isfinite(value):
        raise CaseError(f"{where}: not a finite number")
    return value


def _read_hdf5(path: Path) -> ParticleFile:
    import h5py

    from ..io.trajectory import open_to_read

    try:
        with open_to_read(path) as f:
            if "position" not in f:
                raise CaseError(f"{path}: the HDF5 particle file needs a dataset 'position' (N,3)")
            for name, item in f.items():  # a dataset read by no one (radii for radius) would be dropped
                if isinstance(item, h5py.Dataset) and name not in HDF5_DATASETS:
                    hint = " (the radii are in radius)" if name.lower() in ("radii", "r", "rad") else ""
                    raise CaseError(
                        f"{path}: unknown dataset {name!r}{hint}; the datasets are position and "
                        f"optionally {', '.join(HDF5_DATASETS[1:])} (groups and attributes are not read)"
                    )

            def numbers(name):
                return np.asarray(f[name], dtype=np.float64) if name in f else None

            def names(name):
                return np.array(f[name].asstr()[()], dtype=str) if name in f else None

            return ParticleFile(
                pos=numbers("position"),
                radius=numbers("radius"),
                velocity=numbers("velocity"),
                angular_velocity=numbers("angular_velocity"),
                material=names("material"),
                group=names("group"),
                fixed=np.asarray(f["fixed"], dtype=bool) if "fixed" in f else None,
            )
    except (OSError, ValueError, TypeError) as exc:
        raise CaseError(f"{path}: not a readable HDF5 particle file ({exc})") from None


def _checked(path: Path, data: ParticleFile) -> ParticleFile:
    pos, radius = data.pos, data.radius
    if pos.ndim != 2 or pos.shape[1] != 3 or pos.shape[0] == 0:
        raise CaseError(f"{path}: positions must be an (N,3) array with N >= 1, got shape {pos.shape}")
    for name in ("pos", "radius", "velocity", "angular_velocity"):
        arr = getattr(data, name)
        if arr is not None and not np.all(np.isfinite(arr)):
            raise CaseError(f"{path}: {'position' if name == 'pos' else name} holds non-finite values")
    if radius is not None:
        bad = np.flatnonzero(radius <= 0)
        if bad.size:
            raise CaseError(f"{path}: radius of particle {bad[0]} is {radius[bad[0]]}; radii must be > 0")
    for name in ("radius", "material", "group", "fixed"):
        arr = getattr(data, name)
        if arr is not None and arr.shape != (pos.shape[0],):
            raise CaseError(f"{path}: {name} must have one value per particle")
    for name in VECTORS:
        arr = getattr(data, name)
        if arr is not None and arr.shape != pos.shape:
            raise CaseError(f"{path}: {name} must be an (N,3) array like position")
    return data
