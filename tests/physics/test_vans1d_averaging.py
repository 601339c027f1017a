"""Layer averaging of the vans1d model (kernels/fluid/layer_averaging.py) against exact values.

A simple cubic lattice of spheres (radius r, spacing a) has, per horizontal area a^2, the circle
pi (r^2 - (z - z_c)^2) at height z of a plane of centres z_c: its layer-averaged solid fraction is
the integral of that over the layer divided by a^2 dz; over one whole lattice period it is
4 pi r^3 / (3 a^3). The integral of the profile over the column is the solid volume to round-off.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sphere_cli.kernels.fluid.layer_averaging import slice_volume
from sphere_cli.physics.fluid.layer_averaging import LayerProfiles, layer_faces

A = 1.0e-3  # lattice spacing [m]
R = 0.45e-3  # sphere radius [m]
SIDE = 4  # spheres per side of a plane


def lattice(planes: int, lift: float = 0.0):
    ij = np.arange(SIDE) * A + 0.5 * A
    x, y, z = np.meshgrid(ij, ij, np.arange(planes) * A + 0.5 * A + lift, indexing="ij")
    pos = np.column_stack([x.ravel(), y.ravel(), z.ravel()])
    return pos, np.full(pos.shape[0], R)


def average(pos, radius, faces, vel=None, drag_coef=None, drag_x=None):
    n = pos.shape[0]
    profiles = LayerProfiles.zeros(faces.size - 1)
    vel = np.zeros((n, 3)) if vel is None else vel
    drag_coef = np.zeros(n) if drag_coef is None else drag_coef
    drag_x = np.zeros(n) if drag_x is None else drag_x
    selected = np.ones(n, dtype=np.uint8)
    profiles.average(pos, vel, radius, selected, drag_coef, drag_x, faces, (SIDE * A) ** 2)
    return profiles


def lattice_fraction(a_z, b_z, centres):
    """Exact layer solid fraction of the lattice, by the antiderivative of the circle area."""

    def antiderivative(s):
        s = np.clip(s, -R, R)
        return math.pi * (R * R * s - s**3 / 3.0)

    total = sum(antiderivative(b_z - c) - antiderivative(a_z - c) for c in centres)
    return total / (A * A * (b_z - a_z))


def test_one_layer_per_lattice_period():
    """Layers of one lattice spacing: every one holds 4 pi r^3/(3 a^3) = 0.3817 exactly."""
    pos, radius = lattice(3)
    prof = average(pos, radius, layer_faces(0.0, 3 * A, 3))
    np.testing.assert_allclose(prof.solid_fraction, 4 * math.pi * R**3 / (3 * A**3), rtol=1e-13)


@pytest.mark.parametrize("stretching", [1.0, 5.0])
def test_lattice_profile_equals_analytic(stretching):
    """Fine layers (regular and stretched, lattice lifted off the layer faces) equal the exact
    layer average, and the layer through the centre plane tends to pi r^2/a^2."""
    pos, radius = lattice(3, lift=0.1 * A)
    faces = layer_faces(0.0, 3.5 * A, 70, stretching)
    prof = average(pos, radius, faces)
    centres = 0.5 * A + 0.1 * A + np.arange(3) * A
    exact = np.array([lattice_fraction(a, b, centres) for a, b in zip(faces[:-1], faces[1:], strict=True)])
    # round-off: the slice volume is a difference of antiderivatives of size pi r^3, so its error
    # is about 1e-16 pi r^3 / (a^2 dz) ~ 1e-15 in solid, whatever the size of the slice
    np.testing.assert_allclose(prof.solid_fraction, exact, rtol=0, atol=1e-13)
    k = np.searchsorted(faces, centres[1]) - 1
    dz = faces[k + 1] - faces[k]
    assert prof.solid_fraction[k] == pytest.approx(math.pi * R**2 / A**2, abs=math.pi / A**2 * dz**2)


def test_profile_integral_is_the_solid_volume():
    """Random polydisperse spheres inside the column, stretched layers: the integral of
    solid over the column is the total solid volume, and the integral of exchange the sum of the
    drag coefficients, to round-off; the volume-weighted velocity of a uniform motion is it."""
    rng = np.random.default_rng(3)
    n = 500
    radius = rng.uniform(0.2e-3, 0.5e-3, n)
    pos = np.column_stack(
        [rng.uniform(0, SIDE * A, n), rng.uniform(0, SIDE * A, n), rng.uniform(0.5e-3, 9.5e-3, n)]
    )
    vel = np.tile([0.3, -0.1, 0.2], (n, 1))
    drag_coef = rng.uniform(1e-6, 1e-5, n)
    faces = layer_faces(0.0, 10e-3, 37, 3.0)
    prof = average(pos, radius, faces, vel, drag_coef, drag_coef * 0.7)
    layer_volume = (SIDE * A) ** 2 * np.diff(faces)
    solid = 4.0 / 3.0 * math.pi * np.sum(radius**3)
    assert np.sum(prof.solid_fraction * layer_volume) == pytest.approx(solid, rel=1e-13)
    assert np.sum(prof.exchange_coefficient * layer_volume) == pytest.approx(drag_coef.sum(), rel=1e-13)
    assert np.sum(prof.drag * layer_volume) == pytest.approx(0.7 * drag_coef.sum(), rel=1e-13)
    occupied = prof.solid_fraction > 0
    np.testing.assert_allclose(prof.vel[occupied], 0.3, rtol=1e-13)


def test_parts_outside_the_column_are_not_counted():
    """A sphere cut by the bottom face counts only its part above it."""
    pos = np.array([[A, A, 0.2 * R]])
    radius = np.array([R])
    faces = layer_faces(0.0, 4 * R, 8)
    prof = average(pos, radius, faces)
    above = slice_volume(0.2 * R, R, 0.0, 1.0)
    assert above < 4 / 3 * math.pi * R**3
    assert np.sum(prof.solid_fraction * (SIDE * A) ** 2 * np.diff(faces)) == pytest.approx(above, rel=1e-13)
    # the slice volume itself: a hemisphere, a whole sphere
    assert slice_volume(0.0, R, 0.0, 1.0) == pytest.approx(2 / 3 * math.pi * R**3, rel=1e-14)
    assert slice_volume(0.0, R, -1.0, 1.0) == pytest.approx(4 / 3 * math.pi * R**3, rel=1e-14)
