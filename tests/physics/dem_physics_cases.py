"""Helpers for the DEM physics tests: build a scene from explicit particles through the public
case-file path (TOML text + a CSV placement file), so every test exercises the real builder.

Not a test module (no test_ prefix); imported by the test files of tests/physics.
"""

from __future__ import annotations

import math
from pathlib import Path

from sphere_cli.api import run_in_memory
from sphere_cli.physics.restitution import (
    HERTZ_ELASTIC_CONTACT_TIME_FACTOR,
    linear_contact_time,
    linear_damping_ratio,
)
from sphere_cli.simulation import advance
from sphere_cli.verify.scenes import case_text, linear_contact, particle_csv, sphere_mass, toml_table

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
    dt_safety: float | None = None,
    stability: str | None = None,
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
    if contact is None:
        contact = linear_contact(kn, e, mu, kt)
    extra_particles = None
    if particle_material is not None:
        density, extra_particles = None, {"material": particle_material}
    text = case_text(
        placement_file=name,
        contact=contact,
        density=density,
        walls=walls,
        wall_friction=wall_friction,
        wall_material=wall_material,
        gravity=gravity,
        lower=lower,
        upper=upper,
        periodic=periodic,
        dt=dt,
        dt_safety=dt_safety,
        stability=stability,
        skin=skin,
        overlap_tolerance=overlap_tolerance,
        extra_particles=extra_particles,
        extra_tables="".join(toml_table("materials", m, array=True) for m in materials),
    )
    (tmp_path / name).write_text(particle_csv(pos, radius, vel))
    return run_in_memory(text, 0, base_dir=tmp_path)
