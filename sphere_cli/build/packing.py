"""Initial particle positions: jittered lattice, random non-overlapping insertion, or a file."""

from __future__ import annotations

import io
import warnings
from pathlib import Path

import numpy as np

from ..config.load import case_error
from ..config.schema import FilePlacement, LatticePlacement, RandomPlacement
from ..errors import CaseError, MissingInputError
from ..kernels.packing import insert_random
from ..physics.neighbors import CELLS_PER_PARTICLE


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
    sites = np.floor((upper - lower - 2.0 * rmax) / spacing + 1e-9).astype(np.int64) + 1
    capacity = int(np.prod(sites))
    if capacity < radius.size:
        raise case_error(
            case,
            ("particles", "count"),
            f"the lattice (particles.placement) holds only {capacity} sites ({sites[0]} x {sites[1]} x "
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
    lo = lower + radius[:, None, None]
    hi = upper - radius[:, None, None]
    cand = lo + (hi - lo) * rng.random((radius.size, placement.max_attempts, 3))
    # cells of one largest diameter, coarser where that would be more than a few per particle
    # (uniform candidates fill them evenly, so a coarser cell only costs a few more checks)
    cell = max(2.0 * radius.max(), (np.prod(upper - lower) / (CELLS_PER_PARTICLE * radius.size)) ** (1 / 3))
    ncell = np.maximum(np.floor((upper - lower) / cell).astype(np.int64), 1)
    pos = np.zeros((radius.size, 3))
    # large spheres first: they are the hardest to fit
    order = np.argsort(-radius, kind="stable")
    placed = insert_random(radius[order], cand[order], lower, cell, ncell, pos)
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


def read_particle_file(placement: FilePlacement, base_dir: Path):
    """Returns (position (N,3), radius (N,) or None, velocity (N,3) or None, angular velocity
    (N,3) or None)."""
    path = Path(placement.path)
    if not path.is_absolute():
        path = base_dir / path
    if not path.is_file():
        raise case_error(
            placement, ("particles", "placement", "path"), f"file not found ({path})", MissingInputError
        )
    if path.suffix.lower() in (".h5", ".hdf5"):
        return _read_hdf5(path)
    return _read_csv(path)


def _read_csv(path: Path):
    try:
        text = path.read_text(encoding="utf-8")
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # numpy warns about blank input; it is reported below
            data = (
                np.genfromtxt(io.StringIO(text), delimiter=",", names=True, dtype=np.float64)
                if text.strip()
                else np.zeros(0)
            )
    except (ValueError, OSError, IndexError) as exc:  # UnicodeDecodeError is a ValueError
        detail = " ".join(str(exc).replace("Some errors were detected !", "").split())
        raise CaseError(f"{path}: not a readable CSV particle file ({detail})") from None
    names = data.dtype.names or ()
    if not {"x", "y", "z"} <= set(names):
        raise CaseError(
            f"{path}: the CSV header must name columns x, y, z (and optionally r, vx, vy, vz, wx, wy, wz); "
            f"got {names}"
        )
    data = np.atleast_1d(data)
    _refuse_unparsed(path, text, data, names)
    pos = np.stack([data["x"], data["y"], data["z"]], axis=1)
    radius = np.asarray(data["r"], dtype=np.float64) if "r" in names else None
    vel, angvel = (_vector(data, names, columns) for columns in (("vx", "vy", "vz"), ("wx", "wy", "wz")))
    return _checked(path, pos, radius, vel, angvel)


def _vector(data, names, columns) -> np.ndarray | None:
    """The (N,3) vector of these three columns, or None if the file has not all three."""
    return np.stack([data[c] for c in columns], axis=1) if set(columns) <= set(names) else None


def _refuse_unparsed(path: Path, text: str, data, names) -> None:
    """A field numpy could not read as a number (it reads it as NaN), or one that is not finite,
    named by its line, column and text."""
    bad = []  # (row, column) of the first bad field of each column
    for c, name in enumerate(names):
        rows = np.flatnonzero(~np.isfinite(data[name]))
        if rows.size:
            bad.append((int(rows[0]), c))
    if not bad:
        return
    row, column = min(bad)
    # the rows numpy read: the lines after the header that are neither blank nor comments
    lines = [(n, line) for n, line in enumerate(text.splitlines(), start=1) if line.split("#")[0].strip()]
    number, line = lines[row + 1]
    fields = line.split("#")[0].split(",")
    field = fields[column].strip() if column < len(fields) else ""
    raise CaseError(
        f"{path}:{number}: column {names[column]} (column {column + 1}) = {field!r}: "
        + ("not a finite number" if field and _is_float(field) else "not a number")
    )


def _is_float(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _read_hdf5(path: Path):
    import h5py

    try:
        with h5py.File(path, "r") as f:
            if "position" not in f:
                raise CaseError(f"{path}: the HDF5 particle file needs a dataset 'position' (N,3)")
            pos = np.asarray(f["position"], dtype=np.float64)
            radius = np.asarray(f["radius"], dtype=np.float64) if "radius" in f else None
            vel = np.asarray(f["velocity"], dtype=np.float64) if "velocity" in f else None
            angvel = np.asarray(f["angular_velocity"], dtype=np.float64) if "angular_velocity" in f else None
    except (OSError, ValueError, TypeError) as exc:
        raise CaseError(f"{path}: not a readable HDF5 particle file ({exc})") from None
    return _checked(path, pos, radius, vel, angvel)


def _checked(path, pos, radius, vel, angvel):
    if pos.ndim != 2 or pos.shape[1] != 3 or pos.shape[0] == 0:
        raise CaseError(f"{path}: positions must be an (N,3) array with N >= 1, got shape {pos.shape}")
    for name, arr in (("position", pos), ("radius", radius), ("velocity", vel), ("angular_velocity", angvel)):
        if arr is not None and not np.all(np.isfinite(arr)):
            raise CaseError(f"{path}: {name} holds non-finite values")
    if radius is not None:
        if radius.shape != (pos.shape[0],):
            raise CaseError(f"{path}: radius must have one value per particle")
        bad = np.flatnonzero(radius <= 0)
        if bad.size:
            raise CaseError(f"{path}: radius of particle {bad[0]} is {radius[bad[0]]}; radii must be > 0")
    for name, arr in (("velocity", vel), ("angular_velocity", angvel)):
        if arr is not None and arr.shape != pos.shape:
            raise CaseError(f"{path}: {name} must be an (N,3) array like position")
    return pos, radius, vel, angvel
