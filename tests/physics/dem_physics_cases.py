"""Helpers for the DEM physics tests: build a scene from explicit particles through the public
case-file path (TOML text + a CSV placement file), so every test exercises the real builder.

Not a test module (no test_ prefix); imported by the test files of tests/physics.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from sphere_cli.api import run_in_memory
from sphere_cli.physics.restitution import linear_contact_time, linear_damping_ratio
from sphere_cli.simulation import advance

__all__ = [
    "advance",
    "make_scene",
    "sphere_mass",
    "clamped_contact_time",
    "linear_contact_time",
    "linear_damping_ratio",
]


def sphere_mass(radius: float, density: float) -> float:
    return density * 4.0 / 3.0 * math.pi * radius**3


def clamped_contact_time(kn: float, m_eff: float, e: float) -> float:
    """Duration of the clamped linear contact calibrated to restitution e [s]."""
    return linear_contact_time(kn, m_eff, linear_damping_ratio(e), clamped=True)


def _vec(v) -> str:
    return "[" + ", ".join(repr(float(x)) for x in v) + "]"


def make_scene(
    tmp_path: Path,
    pos,
    radius,
    vel=None,
    *,
    density: float = 2500.0,
    kn: float = 1.0e3,
    kt: float | None = None,
    e: float = 0.5,
    mu: float = 0.5,
    walls=(),
    wall_friction: dict | None = None,
    gravity=(0.0, 0.0, 0.0),
    lower=(0.0, 0.0, 0.0),
    upper=(0.1, 0.1, 0.1),
    periodic=(False, False, False),
    dt: float | str = "auto",
    dt_safety: float = 0.1,
    skin: float = 0.4,
    overlap_tolerance: float = 0.05,
    name: str = "particles.csv",
):
    """Build a scene (advanced 0 steps) holding exactly the given particles.

    pos (N,3) [m], radius (N,) or scalar [m], vel (N,3) or None [m/s]; walls: faces like "z-";
    wall_friction: face -> mu for walls whose friction differs from the contact's.
    """
    pos = np.atleast_2d(np.asarray(pos, dtype=np.float64))
    n = pos.shape[0]
    radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), (n,))
    vel = np.zeros((n, 3)) if vel is None else np.broadcast_to(np.asarray(vel, dtype=np.float64), (n, 3))
    csv = tmp_path / name
    rows = ["x,y,z,r,vx,vy,vz"]
    for p, r, v in zip(pos, radius, vel, strict=True):
        # repr round-trips float64 exactly, so the scene holds exactly these numbers
        rows.append(",".join(repr(float(x)) for x in (*p, r, *v)))
    csv.write_text("\n".join(rows) + "\n")
    dt_text = '"auto"' if dt == "auto" else repr(float(dt))
    kt_text = "" if kt is None else f"tangential_stiffness = {float(kt)!r}\n"
    periodic_text = "[" + ", ".join("true" if p else "false" for p in periodic) + "]"
    wall_friction = wall_friction or {}
    wall_text = ""
    for face in walls:
        wall_text += f'[[walls]]\nface = "{face}"\n'
        if face in wall_friction:
            wall_text += f"friction = {float(wall_friction[face])!r}\n"
    text = f"""
[simulation]
duration = 1.0
dt = {dt_text}
dt_safety = {float(dt_safety)!r}
neighbor_skin = {float(skin)!r}

[domain]
lower = {_vec(lower)}
upper = {_vec(upper)}
periodic = {periodic_text}
gravity = {_vec(gravity)}

[particles]
density = {float(density)!r}
overlap_tolerance = {float(overlap_tolerance)!r}
placement = {{ method = "file", path = "{csv.name}" }}

[contact]
model = "linear"
normal_stiffness = {float(kn)!r}
{kt_text}restitution = {float(e)!r}
friction = {float(mu)!r}

{wall_text}
"""
    return run_in_memory(text, 0, base_dir=tmp_path)
