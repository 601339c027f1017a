"""Helpers for the DEM physics tests: build a scene from explicit particles through the public
case-file path (TOML text + a CSV placement file), so every test exercises the real builder.

Not a test module (no test_ prefix); imported by the test files of tests/physics.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from sphere_cli.api import run_in_memory
from sphere_cli.physics.restitution import (
    HERTZ_ELASTIC_CONTACT_TIME_FACTOR,
    linear_contact_time,
    linear_damping_ratio,
)
from sphere_cli.simulation import advance

__all__ = [
    "advance",
    "make_scene",
    "sphere_mass",
    "clamped_contact_time",
    "linear_contact_time",
    "linear_damping_ratio",
    "hertz_contact",
    "hertz_reference",
]


def sphere_mass(radius: float, density: float) -> float:
    return density * 4.0 / 3.0 * math.pi * radius**3


def hertz_reference(e_star: float, r_eff: float, m_eff: float, v: float) -> dict:
    """A2: peak overlap [m], peak force [N] and duration [s] of the elastic impact at speed v."""
    delta = (15.0 * m_eff * v**2 / (16.0 * e_star * math.sqrt(r_eff))) ** 0.4
    return {
        "delta_max": delta,
        "force_max": 4.0 / 3.0 * e_star * math.sqrt(r_eff) * delta**1.5,
        "contact_time": HERTZ_ELASTIC_CONTACT_TIME_FACTOR * delta / v,
    }


def hertz_contact(
    youngs_modulus: float, poisson_ratio: float, e: float = 1.0, mu: float = 0.0, **more
) -> dict:
    """The [contact] keys of a Hertz-Mindlin law (for make_scene)."""
    return {
        "model": "hertz-mindlin",
        "youngs_modulus": youngs_modulus,
        "poisson_ratio": poisson_ratio,
        "restitution": e,
        "friction": mu,
        **more,
    }


def clamped_contact_time(kn: float, m_eff: float, e: float) -> float:
    """Duration of the clamped linear contact calibrated to restitution e [s]."""
    return linear_contact_time(kn, m_eff, linear_damping_ratio(e), clamped=True)


def _vec(v) -> str:
    return "[" + ", ".join(repr(float(x)) for x in v) + "]"


def _toml(value) -> str:
    """A Python value as a TOML value (floats written exactly, tables inline)."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, str):
        return f'"{value}"'
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {_toml(v)}" for k, v in value.items()) + " }"
    if isinstance(value, list | tuple):
        return "[" + ", ".join(_toml(v) for v in value) + "]"
    return repr(float(value))


def _table(header: str, keys: dict) -> str:
    return f"{header}\n" + "".join(f"{k} = {_toml(v)}\n" for k, v in keys.items())


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
    contact: dict | None = None,
    materials=(),
    particle_material=None,
    wall_material: dict | None = None,
):
    """Build a scene (advanced 0 steps) holding exactly the given particles.

    pos (N,3) [m], radius (N,) or scalar [m], vel (N,3) or None [m/s]; walls: faces like "z-";
    wall_friction: face -> mu for walls whose friction differs from the contact's.
    contact: the keys of [contact] (e.g. a Hertz-Mindlin law), replacing the linear law built from
    kn, kt, e, mu; materials: dicts, one [[materials]] table each; particle_material: the value of
    particles.material (then `density` is not written); wall_material: face -> material name.
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
    periodic_text = "[" + ", ".join("true" if p else "false" for p in periodic) + "]"
    wall_friction = wall_friction or {}
    wall_material = wall_material or {}
    wall_text = ""
    for face in walls:
        wall_text += f'[[walls]]\nface = "{face}"\n'
        if face in wall_friction:
            wall_text += f"friction = {float(wall_friction[face])!r}\n"
        if face in wall_material:
            wall_text += f'material = "{wall_material[face]}"\n'
    if contact is None:
        contact = {"model": "linear", "normal_stiffness": kn, "restitution": e, "friction": mu}
        if kt is not None:
            contact["tangential_stiffness"] = kt
    contact_text = _table("[contact]", contact)
    contact_text += "".join(_table("[[materials]]", m) for m in materials)
    if particle_material is None:
        what = f"density = {float(density)!r}"
    else:
        what = f"material = {_toml(particle_material)}"
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
{what}
overlap_tolerance = {float(overlap_tolerance)!r}
placement = {{ method = "file", path = "{csv.name}" }}

{contact_text}
{wall_text}
"""
    return run_in_memory(text, 0, base_dir=tmp_path)
