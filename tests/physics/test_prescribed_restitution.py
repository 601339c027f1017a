"""Restitution against prescribed-motion bodies: a sphere dropped head-on on an equal
sphere that is fixed, driven at a constant velocity, or glued to a rough wall rebounds with the
restitution asked, as on a plain wall, for linear and Hertz contacts.

The dashpot is calibrated for the reduced mass of the contact. A prescribed body moves as if its
mass were infinite (its inverse mass is 0), so the reduced mass is the free sphere's own,
m* = 1/(1/m + 0) = m; the two finite masses would give m/2, and with the linear law e = 0.60
where 0.50 was asked. The measured e is the ratio of the normal relative velocities after and
before the contact, in a scene without gravity; the tolerance 0.01 is the required one, ten times
the calibration error of a free pair at the automatic dt (tests/physics/test_dem_linear_collision.py).
"""

from __future__ import annotations

import textwrap

import numpy as np
import pytest

from sphere_cli.api import run_in_memory

R = 0.001  # m
V_IN = 0.1  # m/s, the free sphere's speed towards the other
GAP = 0.05 * R  # m between the surfaces at the start
E = 0.5

LAWS = {
    "linear": 'model = "linear"\nnormal_stiffness = 1.0e4\n',
    "hertz": 'model = "hertz-mindlin"\nyoungs_modulus = 1.0e8\npoisson_ratio = 0.3\n',
}


def _case(law: str, body: str, spheres: str) -> str:
    return (
        textwrap.dedent(
            """
        [simulation]
        duration = 1.0
        [domain]
        upper = [0.01, 0.01, 0.01]
        gravity = [0.0, 0.0, 0.0]
        [particles]
        density = 2500.0
        placement = {{ method = "file", path = "{spheres}" }}
        {body}
        [contact]
        restitution = {e}
        friction = 0.0
        """
        ).format(body=body, spheres=spheres, e=E)
        + LAWS[law]
    )


def _rebound(tmp_path, law: str, body: str, rows: list, steps_after: int = 1) -> tuple:
    """(the free sphere's velocity after the contact, the scene), from rows (x, y, z, vz)."""
    csv = tmp_path / "spheres.csv"
    csv.write_text("x,y,z,r,vx,vy,vz\n" + "".join(f"{x},{y},{z},{R},0,0,{vz}\n" for x, y, z, vz in rows))
    text = _case(law, body, csv.name)
    scene = run_in_memory(text, 0, tmp_path)
    dt = scene.state.clock.dt
    # the approach, the contact (well under 2e-3 s for both laws here) and a margin
    scene = run_in_memory(text, int(4e-3 / dt), tmp_path)
    return scene.state.particles.vel[0].copy(), scene


@pytest.mark.parametrize("law", LAWS)
def test_on_a_fixed_sphere(tmp_path, law):
    body = (
        "[[particles.groups]]\nregion_lower = [0.0, 0.0, 0.0]\nregion_upper = [0.01, 0.01, 0.004]\n"
        'motion = "fixed"\n'
    )
    z_fixed = 0.003
    velocity, _ = _rebound(
        tmp_path, law, body, [(0.005, 0.005, z_fixed + 2 * R + GAP, -V_IN), (0.005, 0.005, z_fixed, 0.0)]
    )
    assert velocity[2] / V_IN == pytest.approx(E, abs=0.01)
    assert np.allclose(velocity[:2], 0.0)


@pytest.mark.parametrize("law", LAWS)
def test_on_a_driven_sphere(tmp_path, law):
    """The other sphere moves up at U (a velocity group): e = (v_out - U)/(V_IN + U)."""
    u = 0.05
    body = (
        "[[particles.groups]]\nregion_lower = [0.0, 0.0, 0.0]\nregion_upper = [0.01, 0.01, 0.004]\n"
        f'motion = "velocity"\nvelocity = [0.0, 0.0, {u}]\n'
    )
    z_driven = 0.003
    velocity, _ = _rebound(
        tmp_path, law, body, [(0.005, 0.005, z_driven + 2 * R + GAP, -V_IN), (0.005, 0.005, z_driven, 0.0)]
    )
    assert (velocity[2] - u) / (V_IN + u) == pytest.approx(E, abs=0.01)


@pytest.mark.parametrize("law", LAWS)
def test_on_a_rough_wall(tmp_path, law):
    """Dropped on one of the spheres glued to a rough floor, centred over it."""
    wall = f'[[walls]]\nface = "z-"\nrough = {{ radius = {R} }}\n'
    probe, scene = _rebound(tmp_path, law, wall, [(0.005, 0.005, 0.005, 0.0)])
    p = scene.state.particles
    glued = np.flatnonzero(p.inv_mass == 0.0)
    assert glued.size > 1
    below = glued[np.argmin(np.hypot(p.pos[glued, 0] - 0.005, p.pos[glued, 1] - 0.005))]
    x, y, z = p.pos[below]
    velocity, _ = _rebound(tmp_path, law, wall, [(x, y, z + 2 * R + GAP, -V_IN)])
    assert velocity[2] / V_IN == pytest.approx(E, abs=0.01)
    assert np.allclose(velocity[:2], 0.0, atol=1e-9)
