"""Kernels of the Darcy model (kernels/fluid/pore_pressure.py, kernels/fluid/darcy.py) on small arrays:
Kozeny-Carman and its clamps, the sign of the skeleton source term, the gradient's boundary
ghosts, and the force on a particle in a linear pressure field (exact: the trilinear
interpolation of an exact gradient). Also run as plain Python (NUMBA_DISABLE_JIT=1)."""

from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from sphere_cli.kernels.fluid.darcy import add_pressure_forces
from sphere_cli.kernels.fluid.pore_pressure import (
    backward_euler_system,
    clamp_porosity,
    kozeny_carman,
    pressure_gradient,
    solid_divergence,
)

ROOT = Path(__file__).resolve().parents[2]
SHAPE = (3, 4, 5)
SPACING = np.array([0.01, 0.02, 0.025])


def test_kozeny_carman_and_clamps():
    phi = np.linspace(0.02, 0.98, np.prod(SHAPE)).reshape(SHAPE)
    used = np.zeros(SHAPE)
    clamped = clamp_porosity(phi, 0.1, 0.9, used)
    assert clamped == np.count_nonzero((phi < 0.1) | (phi > 0.9)) > 0
    assert np.array_equal(used, np.clip(phi, 0.1, 0.9))
    k = np.zeros(SHAPE)
    kozeny_carman(used, 2.0e-9, k)
    np.testing.assert_allclose(k, 2.0e-9 * used**3 / (1 - used) ** 2, rtol=1e-15)


def test_compaction_raises_the_pressure():
    """b - c p = -mu div v_s = -mu (dphi/dt + v.grad phi)/(1-phi): positive where the skeleton
    compacts."""
    p = np.full(SHAPE, 7.0)
    phi = np.full(SHAPE, 0.4)
    rate = np.full(SHAPE, -2.0)  # 1/s
    vbar = np.zeros(SHAPE + (3,))
    c, b, source = np.zeros(SHAPE), np.zeros(SHAPE), np.zeros(SHAPE)
    beta, mu, dt = 4.5e-10, 1e-3, 1e-5
    none = np.zeros(3, np.uint8)
    solid_divergence(phi, phi, rate, vbar, 1 / SPACING, none, source)
    backward_euler_system(p, phi, source, beta, mu, dt, c, b)
    np.testing.assert_allclose(c, beta * 0.4 * mu / dt, rtol=1e-15)
    np.testing.assert_allclose(b - c * p, mu * 2.0 / 0.6, rtol=1e-12)
    # advection: a skeleton moving up (+z) into a porosity that grows with z: D phi / Dt > 0
    phi_z = np.broadcast_to(0.3 + 0.02 * np.arange(SHAPE[2]), SHAPE).copy()
    vbar[..., 2] = 0.1
    rate[...] = 0.0
    solid_divergence(phi_z, phi_z, rate, vbar, 1 / SPACING, none, source)
    backward_euler_system(p, phi_z, source, beta, mu, dt, c, b)
    np.testing.assert_allclose(b - c * p, -mu * 0.1 * (0.02 / SPACING[2]) / (1 - phi_z), rtol=1e-12)


def linear_field(slope):
    centres = [(np.arange(n) + 0.5) * h for n, h in zip(SHAPE, SPACING, strict=True)]
    x, y, z = np.meshgrid(*centres, indexing="ij")
    return slope[0] * x + slope[1] * y + slope[2] * z + 3.0


def test_gradient_ghosts_and_force_in_a_linear_field():
    """A field linear in z between Dirichlet faces holding its values: the gradient is exact in
    every cell. p = a.x + p0: exact in the interior cells; the no-flow mirror ghosts halve it in
    the boundary cells of x and y. The force on any particle between interior cell centres is
    -V a - rho_f V g."""
    slope = np.array([30.0, -20.0, 50.0])
    ih, none = 1 / SPACING, np.zeros(3, np.uint8)
    grad = np.zeros(SHAPE + (3,))
    bottom, top = 3.0, 3.0 + slope[2] * SHAPE[2] * SPACING[2]
    pressure_gradient(linear_field(slope * [0, 0, 1]), ih, none, np.uint8(1), np.uint8(1), bottom, top, grad)
    np.testing.assert_allclose(grad[..., 2], slope[2], rtol=1e-12)
    np.testing.assert_allclose(grad[..., :2], 0.0, atol=1e-12)
    pressure_gradient(linear_field(slope), ih, none, np.uint8(0), np.uint8(0), 0.0, 0.0, grad)
    inner = grad[1:-1, 1:-1, 1:-1]
    np.testing.assert_allclose(inner, np.broadcast_to(slope, inner.shape), rtol=1e-12)
    np.testing.assert_allclose(grad[0, 1:-1, 1:-1, 0], 0.5 * slope[0], rtol=1e-12)
    np.testing.assert_allclose(grad[1:-1, -1, 1:-1, 1], 0.5 * slope[1], rtol=1e-12)
    rng = np.random.default_rng(3)
    n = 50
    lo, hi = 1.5 * SPACING, (np.array(SHAPE) - 1.5) * SPACING  # between interior centres
    pos = lo + rng.random((n, 3)) * (hi - lo)
    radius = rng.uniform(1e-4, 2e-3, n)
    gravity = np.array([0.0, 0.0, -9.81])
    volume = 4.0 / 3.0 * math.pi * radius**3
    buoyancy = -1000.0 * volume[:, None] * gravity[None, :]
    # the seepage force -V grad p / (1 - phi), phi interpolated like grad p (linear in x here:
    # exact), and the original sphere's -V grad p
    phi = linear_field(np.array([1000.0, 0.0, 0.0])) * 0.01  # 0.08 .. 0.28 at the centres
    expected_phi = (1000.0 * pos[:, 0] + 3.0) * 0.01
    for whole, share in ((1, 1.0 / (1.0 - expected_phi)), (0, 1.0)):
        force = np.zeros((n, 3))
        add_pressure_forces(
            pos, radius, grad, phi, np.uint8(whole), np.zeros(3), SPACING, np.zeros(3, np.uint8), 1000.0,
            gravity, force,
        )  # fmt: skip
        expected = -(share * volume)[:, None] * slope[None, :] + buoyancy
        np.testing.assert_allclose(force, expected, rtol=1e-10)


def test_a_periodic_axis_interpolates_across_its_ends():
    """Along periodic x and y the force blends the last cell with the first: a particle a
    quarter cell beyond the last centre, or the same distance before the first (and a period
    away), feels 3/4 of the last cell's gradient and 1/4 of the first's; along bounded z one
    beyond the outer centres feels the outer cell's alone."""
    rng = np.random.default_rng(5)
    grad = rng.uniform(-100.0, 100.0, SHAPE + (3,))
    phi = np.zeros(SHAPE)
    h, (nx, ny, _) = SPACING, SHAPE
    # (x, y) a quarter cell past the last centre, its images, and z below the lowest centre
    pos = np.array([[(nx - 0.25) * h[0], (ny - 0.25) * h[1], 0.2 * h[2]],
                    [-0.25 * h[0], -0.25 * h[1], 0.2 * h[2]],
                    [(2 * nx - 0.25) * h[0], (-ny - 0.25) * h[1], 0.2 * h[2]]])  # fmt: skip
    radius = np.full(3, 1e-3)
    force = np.zeros((3, 3))
    periodic = np.array([1, 1, 0], np.uint8)
    none = np.zeros(3)
    add_pressure_forces(pos, radius, grad, phi, np.uint8(0), none, h, periodic, 0.0, none, force)
    corners = grad[[nx - 1, 0]][:, [ny - 1, 0], 0]  # (x end, y end, component)
    weights = np.array([0.75, 0.25])
    expected = -(4.0 / 3.0 * math.pi * 1e-9) * np.einsum("i,j,ijc->c", weights, weights, corners)
    for row in force:
        np.testing.assert_allclose(row, expected, rtol=1e-12)


def test_kernels_run_as_plain_python():
    """The same tests with NUMBA_DISABLE_JIT=1 (the kernels are valid Python)."""
    env = dict(os.environ, NUMBA_DISABLE_JIT="1", PYTHONPATH=str(ROOT))
    test = Path(__file__).resolve()
    names = "not plain_python"
    subprocess.run(
        [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", str(test), "-k", names],
        env=env,
        check=True,
        capture_output=True,
    )
