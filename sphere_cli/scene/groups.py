"""Particle groups of a new scene: the prescribed motion of [[particles.groups]] and of the
placement file's group and fixed columns."""

from __future__ import annotations

import numpy as np


def apply_groups(
    case,
    pos: np.ndarray,
    vel: np.ndarray,
    angvel: np.ndarray,
    inv_mass: np.ndarray,
    inv_inertia: np.ndarray,
    names: np.ndarray | None = None,
    fixed: np.ndarray | None = None,
) -> None:
    """Give the particles of each [[particles.groups]] entry (inside its region, or of its name
    in the placement file's group column `names`) their prescribed motion: no response to forces
    (inv_mass = inv_inertia = 0), no spin, a fixed velocity (zero if fixed); a later group wins,
    and a particle the file's `fixed` column marks never moves."""
    for group in case.particles.groups:
        inside = np.zeros(pos.shape[0], dtype=bool)
        if group.region_lower is not None:
            lower, upper = np.array(group.region_lower), np.array(group.region_upper)
            inside |= np.all((pos >= lower) & (pos <= upper), axis=1)
        if group.name is not None and names is not None:
            inside |= names == group.name
        velocity = 0.0 if group.motion == "fixed" else group.velocity
        _prescribe(inside, vel, angvel, inv_mass, inv_inertia, velocity)
    if fixed is not None:
        _prescribe(fixed, vel, angvel, inv_mass, inv_inertia, 0.0)


def _prescribe(inside, vel, angvel, inv_mass, inv_inertia, velocity) -> None:
    inv_mass[inside] = 0.0
    inv_inertia[inside] = 0.0
    vel[inside] = np.asarray(velocity, dtype=float)
    angvel[inside] = 0.0
