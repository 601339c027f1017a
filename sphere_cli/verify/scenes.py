"""Exact scenes for verification: explicit particles through the public case-file path.

A scene is written as TOML text plus a CSV placement file (repr() round-trips float64, so the
scene holds exactly the given numbers) and built by the real builder, so every verification
case exercises the same code as `sphere run`.
"""

from __future__ import annotations

import math
import tempfile
from pathlib import Path

import numpy as np

from ..config.load import parse_case
from ..scene.builder import build_scene


def sphere_mass(radius: float, density: float) -> float:
    """m = (4/3) pi rho R^3 [kg]."""
    return density * 4.0 / 3.0 * math.pi * radius**3


def toml_value(value) -> str:
    """A Python scalar, string or list as a TOML value."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, int | float | np.floating | np.integer):
        return repr(float(value)) if isinstance(value, float | np.floating) else str(int(value))
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, list | tuple | np.ndarray):
        return "[" + ", ".join(toml_value(v) for v in value) + "]"
    if isinstance(value, dict):
        return "{ " + ", ".join(f"{k} = {toml_value(v)}" for k, v in value.items()) + " }"
    raise TypeError(f"cannot write {value!r} as TOML")


def toml_table(name: str, entries: dict, array: bool = False) -> str:
    """[name] (or [[name]] with array=True) with one key per line; None values are left out."""
    head = f"[[{name}]]" if array else f"[{name}]"
    lines = [head] + [f"{k} = {toml_value(v)}" for k, v in entries.items() if v is not None]
    return "\n".join(lines) + "\n"


def linear_contact(kn: float, e: float, mu: float, kt: float | None = None) -> dict:
    """The [contact] table of the linear spring-dashpot law."""
    return {
        "model": "linear",
        "normal_stiffness": float(kn),
        "tangential_stiffness": None if kt is None else float(kt),
        "restitution": float(e),
        "friction": float(mu),
    }


def case_text(
    *,
    placement_file: str,
    contact: dict,
    density: float | None = 2500.0,
    walls=(),
    wall_friction: dict | None = None,
    wall_material: dict | None = None,
    gravity=(0.0, 0.0, 0.0),
    lower=(0.0, 0.0, 0.0),
    upper=(0.1, 0.1, 0.1),
    periodic=(False, False, False),
    dt: float | str = "auto",
    dt_safety: float | None = None,
    stability: str | None = None,
    skin: float = 0.4,
    overlap_tolerance: float = 0.05,
    duration: float = 1.0,
    blowup_check_every: int = 100,
    extra_particles: dict | None = None,
    extra_tables: str = "",
) -> str:
    """Case-file text for explicit particles read from `placement_file` (CSV next to the case).

    wall_friction, wall_material: face -> the wall's friction / material name where given;
    extra_particles: more keys of [particles] (e.g. species); extra_tables: TOML appended as is
    (materials and other tables of models that need them)."""
    wall_friction = wall_friction or {}
    wall_material = wall_material or {}
    walls_text = "".join(
        toml_table(
            "walls",
            {"face": face, "friction": wall_friction.get(face), "material": wall_material.get(face)},
            array=True,
        )
        for face in walls
    )
    particles = {
        "density": density,
        "overlap_tolerance": float(overlap_tolerance),
        "placement": {"method": "file", "path": placement_file},
        **(extra_particles or {}),
    }
    return "\n".join(
        [
            toml_table(
                "simulation",
                {
                    "duration": float(duration),
                    "dt": dt if dt == "auto" else float(dt),
                    "dt_safety": None if dt_safety is None else float(dt_safety),
                    "stability": stability,
                    "neighbor_skin": float(skin),
                    "blowup_check_every": int(blowup_check_every),
                },
            ),
            toml_table(
                "domain",
                {
                    "lower": [float(x) for x in lower],
                    "upper": [float(x) for x in upper],
                    "periodic": [bool(p) for p in periodic],
                    "gravity": [float(x) for x in gravity],
                },
            ),
            toml_table("particles", particles),
            toml_table("contact", contact),
            walls_text,
            extra_tables,
        ]
    )


def particle_csv(pos, radius, vel=None, columns: dict | None = None) -> str:
    """CSV text x,y,z,r,vx,vy,vz (+ extra per-particle columns) with exact float64 values."""
    pos = np.atleast_2d(np.asarray(pos, dtype=np.float64))
    n = pos.shape[0]
    radius = np.broadcast_to(np.asarray(radius, dtype=np.float64), (n,))
    vel = np.zeros((n, 3)) if vel is None else np.broadcast_to(np.asarray(vel, dtype=np.float64), (n, 3))
    columns = columns or {}
    header = ["x", "y", "z", "r", "vx", "vy", "vz", *columns]
    rows = [",".join(header)]
    for i in range(n):
        values = [*pos[i], radius[i], *vel[i]] + [columns[c][i] for c in columns]
        rows.append(",".join(repr(float(x)) for x in values))
    return "\n".join(rows) + "\n"


def build_from_text(text: str, csv: str):
    """Build the scene of case `text` whose placement file (placement.csv) holds `csv`."""
    with tempfile.TemporaryDirectory(prefix="sphere-verify-") as tmp:
        folder = Path(tmp)
        (folder / "placement.csv").write_text(csv, encoding="utf-8")
        (folder / "case.toml").write_text(text, encoding="utf-8")
        return build_scene(parse_case(text, folder / "case.toml"))


def particle_scene(pos, radius, vel=None, *, contact: dict, columns: dict | None = None, **case_keys):
    """Scene (at step 0, initial forces computed) holding exactly the given particles.

    pos (N,3) [m], radius (N,) or scalar [m], vel (N,3) or None [m/s]; contact: the [contact]
    table (e.g. linear_contact(...)); other keywords as in case_text."""
    text = case_text(placement_file="placement.csv", contact=contact, **case_keys)
    return build_from_text(text, particle_csv(pos, radius, vel, columns))
