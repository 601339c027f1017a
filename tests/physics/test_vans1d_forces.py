"""Fluid forces of the vans1d model on single spheres (kernels/fluid/profile_forces.py), against the
closed forms of YADE's HydroForceEngine (Maurin et al. 2015): drag 1/2 C_d A rho |u_r| u_r with
C_d = (0.44 + 24/Re_p)(1 - solid)^-n, buoyancy -rho V g (or its z part), lift
1/2 rho C_L A (u_top^2 - u_bottom^2) (Wiberg & Smith 1985).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sphere_cli.kernels.fluid.profile_forces import bracket, fluid_velocity_at, profile_forces
from sphere_cli.physics.fluid.layer_averaging import layer_faces

RHO, NU, R = 1000.0, 1.0e-6, 0.5e-3
GRAVITY = np.array([0.5, 0.0, -9.8])


def forces(z, vel, u_of_z, solid=0.0, full=False, lift=0.0, top=0.02, exponent=3.1, fluct=None):
    faces = layer_faces(0.0, top, 200)
    centres = 0.5 * (faces[1:] + faces[:-1])
    u = u_of_z(centres)
    pos = np.array([[0.0, 0.0, z]])
    force = np.zeros((1, 3))
    coef, drag_x = np.zeros(1), np.zeros(1)
    profile_forces(
        pos, np.array([vel], dtype=float), np.array([R]), np.ones(1, np.uint8), faces, centres, u,
        np.full(centres.size, solid), False, 0.0, RHO, NU, exponent, 0.61, GRAVITY, full, lift,
        fluct is not None, np.array([fluct if fluct is not None else (0.0, 0.0, 0.0)], dtype=float), force,
        coef, drag_x,
    )  # fmt: skip
    return force[0], coef[0], drag_x[0], (faces, centres, u)


def test_drag_and_buoyancy_in_uniform_flow():
    volume, area = 4 / 3 * math.pi * R**3, math.pi * R**2
    vel = (0.1, 0.02, -0.03)
    f, coef, drag_x, _ = forces(0.01, vel, lambda z: np.full_like(z, 0.5), solid=0.3)
    rel = np.array([0.5, 0.0, 0.0]) - vel
    speed = np.linalg.norm(rel)
    cd = (0.44 + 24 * NU / (speed * 2 * R)) * (1 - 0.3) ** -3.1
    drag = 0.5 * cd * area * RHO * speed * rel
    buoyancy = np.array([0.0, 0.0, RHO * volume * 9.8])  # wall-normal part only
    np.testing.assert_allclose(f, drag + buoyancy, rtol=1e-13)
    assert drag_x == pytest.approx(drag[0], rel=1e-13)
    assert coef == pytest.approx(drag[0] / rel[0], rel=1e-13)
    f_full, *_ = forces(0.01, vel, lambda z: np.full_like(z, 0.5), solid=0.3, full=True)
    np.testing.assert_allclose(f_full - f, [-RHO * volume * 0.5, 0.0, 0.0], rtol=1e-12)


def test_hindrance_is_capped_at_the_packed_solid_fraction():
    f_cap, *_ = forces(0.01, (0, 0, 0), lambda z: np.full_like(z, 0.5), solid=0.61)
    f_over, *_ = forces(0.01, (0, 0, 0), lambda z: np.full_like(z, 0.5), solid=0.9)
    assert f_over[0] == f_cap[0]


def test_half_submerged_sphere_and_sphere_in_air():
    """A sphere centred on the surface feels half of every force; one above it, none."""
    f_deep, *_ = forces(0.01, (0, 0, 0), lambda z: np.full_like(z, 0.5))
    f_half, *_ = forces(0.02, (0, 0, 0), lambda z: np.full_like(z, 0.5))
    f_air, coef, *_ = forces(0.02 + 1.01 * R, (0, 0, 0), lambda z: np.full_like(z, 0.5))
    np.testing.assert_allclose(f_half, 0.5 * f_deep, rtol=1e-12)
    assert not f_air.any() and coef == 0.0


def test_lift_in_a_linear_shear():
    """u = G z at rest: u_top^2 - u_bottom^2 = 4 G^2 z R, so f_L = 2 rho C_L pi R^3 G^2 z."""
    shear, z, cl = 40.0, 0.01, 0.2
    f_lift, *_ = forces(z, (0, 0, 0), lambda zz: shear * zz, lift=cl)
    f_none, *_ = forces(z, (0, 0, 0), lambda zz: shear * zz)
    expected = 0.5 * RHO * cl * math.pi * R**2 * 4 * shear**2 * z * R
    assert f_lift[2] - f_none[2] == pytest.approx(expected, rel=1e-10)


def test_profile_boundaries():
    """u vanishes at the no-slip bottom (linearly from the first centre), is constant above the
    last centre under a free surface and goes linearly to the velocity of a no-slip lid."""
    faces = layer_faces(0.0, 1.0, 4)
    centres = 0.5 * (faces[1:] + faces[:-1])
    u = np.array([1.0, 2.0, 3.0, 4.0])
    assert fluid_velocity_at(faces, centres, u, False, 0.0, 0.0) == 0.0
    assert fluid_velocity_at(faces, centres, u, False, 0.0, 0.0625) == pytest.approx(0.5)
    assert fluid_velocity_at(faces, centres, u, False, 0.0, 0.5) == pytest.approx(2.5)
    assert fluid_velocity_at(faces, centres, u, False, 0.0, 0.95) == 4.0
    assert fluid_velocity_at(faces, centres, u, True, 0.0, 0.9375) == pytest.approx(2.0)
    assert fluid_velocity_at(faces, centres, u, True, 0.0, 1.0) == 0.0
    assert fluid_velocity_at(faces, centres, u, True, 0.5, 1.0) == 0.5  # a lid moving at 0.5 m/s
    assert fluid_velocity_at(faces, centres, u, True, 0.5, 0.9375) == pytest.approx(2.25)


def test_forces_do_not_depend_on_the_thread_count():
    """Each particle's forces are computed by itself (gather): 1 and 2 threads agree bitwise."""
    import numba

    rng = np.random.default_rng(2)
    n = 400
    faces = layer_faces(0.0, 0.02, 30, 3.0)
    centres = 0.5 * (faces[1:] + faces[:-1])
    pos = rng.uniform(0.0, 0.021, (n, 3))
    vel = rng.normal(0.0, 0.1, (n, 3))
    radius = rng.uniform(0.4e-3, 0.6e-3, n)
    u, solid = rng.uniform(0, 1, centres.size), rng.uniform(0, 0.6, centres.size)
    results = []
    for threads in (1, min(2, numba.config.NUMBA_NUM_THREADS)):
        numba.set_num_threads(threads)
        force, coef, drag_x = np.zeros((n, 3)), np.zeros(n), np.zeros(n)
        profile_forces(
            pos, vel, radius, np.ones(n, np.uint8), faces, centres, u, solid, False, 0.0, RHO, NU, 3.1, 0.61,
            GRAVITY, True, 0.2, False, np.zeros((1, 3)), force, coef, drag_x,
        )  # fmt: skip
        results.append((force, coef, drag_x))
    for a, b in zip(*results, strict=True):
        assert np.array_equal(a, b)


def test_a_turbulent_fluctuation_adds_to_the_fluid_velocity_the_particle_sees():
    """The drag of a particle at velocity v in a fluctuation f is that of one at v - f without
    it (buoyancy and the profile unchanged)."""
    fluct, vel = (0.03, -0.02, 0.015), np.array([0.1, 0.01, -0.005])
    with_fluct = forces(0.008, vel, lambda z: 0.4 + 0 * z, solid=0.2, fluct=fluct)
    shifted = forces(0.008, vel - np.array(fluct), lambda z: 0.4 + 0 * z, solid=0.2)
    for a, b in zip(with_fluct[:3], shifted[:3], strict=True):
        np.testing.assert_allclose(a, b, rtol=1e-13)


def _bisection(centres, z):
    """The bracket by plain bisection: the unique lo with centres[lo] <= z < centres[lo + 1]."""
    n = len(centres)
    if z <= centres[0]:
        return 0, 0, 0.0
    if z >= centres[-1]:
        return n - 1, n - 1, 0.0
    lo = int(np.searchsorted(centres, z, side="right")) - 1
    return lo, lo + 1, (z - centres[lo]) / (centres[lo + 1] - centres[lo])


@pytest.mark.parametrize("layers", [2, 3, 7, 900])
@pytest.mark.parametrize("stretching", [1.0, 1.5, 20.0])
def test_bracket_starts_from_even_spacing_and_finds_the_bisection_bracket(layers, stretching):
    """The guess from evenly spaced centres is only a start: on stretched layers, at the centres
    and one rounding step either side of them, the bracket is the bisection's, bitwise."""
    faces = layer_faces(0.0, 0.17, layers, stretching)
    centres = 0.5 * (faces[1:] + faces[:-1])
    z = np.concatenate(
        [
            np.random.default_rng(layers).uniform(-0.01, 0.18, 2000),
            centres,
            faces,
            np.nextafter(centres, 1.0),
            np.nextafter(centres, -1.0),
        ]
    )
    for height in z:
        assert bracket(centres, height) == _bisection(centres, height)
