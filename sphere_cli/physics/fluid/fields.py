"""Fluid fields a case file gives (`[fluid.initial]` and `[fluid.body_force]` of the
Navier-Stokes model): expressions of position (config/expression.py) evaluated where each
quantity lives on the staggered grid, a velocity or acceleration component on the faces normal
to it and the pressure at the cell centres, or the same arrays read from an HDF5 file.

A value that is not finite, an unreadable file, a dataset of the wrong shape: a CaseError naming
the key (exit 65); a file that does not exist: MissingInputError (exit 66).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ...config.expression import ExpressionError, parse
from ...errors import CaseError, MissingInputError
from ...io.trajectory import open_to_read

COMPONENTS = ("x", "y", "z")


def face_shape(grid, c: int) -> tuple[int, int, int]:
    """The faces of velocity component c: (nx, ny, nz), with nz + 1 layers for c = 2."""
    nx, ny, nz = grid.shape
    return (nx, ny, nz + 1) if c == 2 else (nx, ny, nz)


def face_expressions(solver, texts, key: tuple, loaded) -> list[np.ndarray]:
    """The three components of `texts` (expressions of x, y, z) on their faces."""
    values = []
    for c, text in enumerate(texts):
        x, y, z = solver.face_coordinates(c)
        values.append(_evaluate(text, x, y, z, face_shape(solver.grid, c), (*key, c), loaded))
    return values


def cell_expression(solver, text: str, key: tuple, loaded) -> np.ndarray:
    """`text` (an expression of x, y, z) at the cell centres."""
    g = solver.grid
    x, y, z = (g.centres(a).reshape([-1 if b == a else 1 for b in range(3)]) for a in range(3))
    return _evaluate(text, x, y, z, tuple(g.shape), key, loaded)


def _evaluate(text, x, y, z, shape, key, loaded) -> np.ndarray:
    try:
        value = parse(text).evaluate(x=x, y=y, z=z)
    except ExpressionError as exc:
        raise loaded.error(key, str(exc)) from None
    return np.broadcast_to(value, shape)


def read_face_fields(text: str, prefix: str, solver, key: tuple, loaded) -> dict[int, np.ndarray]:
    """The datasets `prefix`_x, _y, _z of the HDF5 file `text` (relative to the case file) on
    their faces, by component (all three required)."""
    shapes = {f"{prefix}_{name}": face_shape(solver.grid, c) for c, name in enumerate(COMPONENTS)}
    arrays = read_grid_file(text, shapes, key, loaded, True)
    return {c: arrays[f"{prefix}_{name}"] for c, name in enumerate(COMPONENTS)}


def read_grid_file(text: str, shapes: dict, key: tuple, loaded, required: bool) -> dict[str, np.ndarray]:
    """Datasets of an HDF5 file (relative to the case file) by name, each checked against its
    shape and for finite values: all of `shapes` when `required`, else those present (at least
    one)."""
    path = Path(text)
    if not path.is_absolute():
        path = loaded.base_dir / path
    if not path.is_file():
        raise MissingInputError(loaded.describe(key, f"file not found ({path})"))
    arrays = {}
    try:
        with open_to_read(path) as f:
            for name, shape in shapes.items():
                if name not in f:
                    if required:
                        raise CaseError(loaded.describe(key, f"{path} has no dataset {name!r} {shape}"))
                    continue
                data = np.asarray(f[name][()], dtype=np.float64)
                if data.shape != shape:
                    raise CaseError(
                        loaded.describe(
                            key,
                            f"{path}: dataset {name!r} has the shape {data.shape}, the fluid grid "
                            f"needs {shape}",
                        )
                    )
                if not np.isfinite(data).all():
                    index = tuple(int(i) for i in np.argwhere(~np.isfinite(data))[0])
                    raise CaseError(
                        loaded.describe(key, f"{path}: dataset {name!r} is not finite at {index}")
                    )
                arrays[name] = data
    except CaseError:
        raise
    except (OSError, ValueError, TypeError) as exc:
        raise CaseError(loaded.describe(key, f"{path}: not a readable HDF5 file ({exc})")) from None
    if not arrays:
        raise CaseError(loaded.describe(key, f"{path} has none of the datasets {', '.join(shapes)}"))
    return arrays
