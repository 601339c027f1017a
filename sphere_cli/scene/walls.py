"""The walls of a new scene: their arrays at the box faces, and the spheres glued to rough walls."""

from __future__ import annotations

import math

import numpy as np

from ..kernels.walls import C_MASS, C_SHEAR_AXIS, NC
from ..physics.walls import AXES
from ..state import Walls


def allocate_walls(
    wall_specs, n_particles: int, lower, upper, wall_table: np.ndarray, moving: bool, springs: bool = True
) -> Walls:
    """Walls at the box faces, every one fixed (modes are set by `apply_modes`). `moving`: some
    wall moves in some stage, so steps record the particles' forces on the moving walls;
    `springs`: some contact has friction, so wall contacts carry tangential springs."""
    faces = [w.face for w in wall_specs]
    nw = len(faces)
    axis = np.array([AXES[f[0]] for f in faces], dtype=np.int64)
    sign = np.array([1.0 if f[1] == "-" else -1.0 for f in faces])
    coord = np.array([lower[a] if s > 0 else upper[a] for a, s in zip(axis, sign, strict=True)])
    control = np.zeros((nw, NC))
    control[:, C_SHEAR_AXIS] = (axis + 1) % 3
    control[:, C_MASS] = 1.0
    return Walls(
        faces=faces,
        axis=axis,
        sign=sign,
        coord=coord,
        table=np.ascontiguousarray(wall_table),
        hist=np.zeros((n_particles if springs else 0, nw, 3)),  # no springs without friction
        vel=np.zeros((nw, 3)),
        acc=np.zeros((nw, 3)),
        shift=np.zeros((nw, 3)),
        force=np.zeros((nw, 3)),
        area=np.zeros(nw),
        mode=np.zeros((nw, 2), dtype=np.int64),
        control=control,
        attached=np.zeros(0, dtype=np.int64),
        attached_wall=np.zeros(0, dtype=np.int64),
        vel_pred=np.zeros((nw, 3)),
        pforce=np.zeros((n_particles if moving else 0, nw, 3)),
        record=np.zeros(nw, dtype=np.uint8),
        fluid_force=np.zeros((nw, 3)),
    )


def rough_layers(case, lower, upper) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Positions (K,3), radii (K,) and wall index (K,) of the spheres glued to the rough walls:
    a square lattice on each wall's plane, spacing stretched so a whole number fits each side
    (the period on a periodic axis, else the face less a radius at each end)."""
    largest = case.particles.radius.largest
    pos, radius, wall = [], [], []
    for w, spec in enumerate(case.walls):
        if spec.rough is None:
            continue
        a = AXES[spec.face[0]]
        r = spec.rough.radius or largest
        pitch = spec.rough.spacing * 2.0 * r
        lines = []
        for b in range(3):
            if b == a:
                lines.append(np.array([lower[a] if spec.face[1] == "-" else upper[a]]))
                continue
            length = upper[b] - lower[b]
            if case.domain.periodic[b]:
                n = max(1, math.floor(length / pitch + 1e-9))
                lines.append(lower[b] + (np.arange(n) + 0.5) * (length / n))
            else:
                n = max(1, math.floor((length - 2.0 * r) / pitch + 1e-9) + 1)
                lines.append(
                    np.linspace(lower[b] + r, upper[b] - r, n)
                    if n > 1
                    else np.array([0.5 * (lower[b] + upper[b])])
                )
        grid = np.stack(np.meshgrid(*lines, indexing="ij"), axis=-1).reshape(-1, 3)
        pos.append(grid)
        radius.append(np.full(grid.shape[0], r))
        wall.append(np.full(grid.shape[0], w, dtype=np.int64))
    if not pos:
        return np.zeros((0, 3)), np.zeros(0), np.zeros(0, dtype=np.int64)
    return np.concatenate(pos), np.concatenate(radius), np.concatenate(wall)
