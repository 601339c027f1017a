"""Observables against closed forms: solid fraction and coordination of a simple cubic lattice,
the granular stress of a resting column (virial theorem) and of a gas (kinetic part)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sphere_cli.api import run_in_memory
from sphere_cli.simulation import advance

R = 1.0e-3
CASE = """
[simulation]
duration = 1.0
dt_safety = 0.2

[domain]
upper = [{lx}, {ly}, {lz}]
periodic = [true, true, false]
gravity = [0.0, 0.0, {g}]

[particles]
count = {n}
density = 2500.0
placement = {{ method = "lattice", spacing = 1.0, jitter = 0.0 }}

[contact]
model = "linear"
normal_stiffness = 1.0e4
restitution = {e}
friction = {mu}

{walls}

[output.observables]
quantities = ["packing_fraction", "coordination", "stress", "profiles"]
layers = {layers}
interior_margin = 0.5
"""
BOTH = '[[walls]]\nface = "z-"\n[[walls]]\nface = "z+"'


def _scene(n, lx, ly, lz, walls, layers=1, g=0.0, e=0.5, mu=0.5):
    text = CASE.format(n=n, lx=lx, ly=ly, lz=lz, walls=walls, layers=layers, g=g, e=e, mu=mu)
    return run_in_memory(text, 0)


def _place(scene, pos):
    state = scene.state
    state.particles.pos[...] = pos
    scene.neighbors.rebuild(state)


def _sample(scene) -> dict:
    return {name: value for name, (value, _unit) in scene.observer.sample().items()}


def _cubic():
    """4 x 4 x 4 spheres of radius R at the centres of 2R cubes filling 8R x 8R x 8R."""
    c = (2.0 * np.arange(4) + 1.0) * R
    return np.array([(x, y, z) for x in c for y in c for z in c])


@pytest.mark.parametrize("mu", [0.0, 0.5])
def test_simple_cubic_fraction_and_coordination(mu):
    """Simple cubic packing: solid fraction pi/6 in the sample and in the interior (spheres cut
    in half by the interior's planes count half, exact caps), the layers' solid volumes add up to
    the spheres' volume; with radii 1 ppm larger each sphere has 6 contacts (walls included) and
    none is a rattler."""
    scene = _scene(64, 8 * R, 8 * R, 8 * R, BOTH, layers=3, mu=mu)
    _place(scene, _cubic())
    obs = _sample(scene)
    assert obs["packing_fraction"] == pytest.approx(math.pi / 6, rel=1e-12)
    assert obs["packing_fraction_interior"] == pytest.approx(math.pi / 6, rel=1e-12)
    layers = obs["packing_fraction_profile"]
    solid = layers.sum() * (8 * R) ** 3 / 3
    assert solid == pytest.approx(64 * 4.0 / 3.0 * math.pi * R**3, rel=1e-12)
    assert layers[0] == pytest.approx(layers[2], rel=1e-12)
    assert obs["coordination"] == 0.0  # exactly touching spheres do not overlap

    scene.state.particles.radius[...] = R * (1.0 + 1e-6)
    _place(scene, _cubic())
    obs = _sample(scene)
    assert obs["coordination"] == 6.0
    assert obs["coordination_no_rattlers"] == 6.0
    assert obs["rattler_fraction"] == 0.0
    # a sphere shrunk by 1 % touches nothing: a rattler. The interior (margin R, from the radii
    # as built) holds the 48 centres at z = R, 3R, 5R, among them all six of its neighbours.
    scene.state.particles.radius[21] *= 0.99  # the site (3R, 3R, 3R)
    obs = _sample(scene)
    assert obs["coordination"] == (48 * 6 - 6 - 6) / 48
    assert obs["coordination_no_rattlers"] == (47 * 6 - 6) / 47
    assert obs["rattler_fraction"] == pytest.approx(1 / 48, rel=1e-12)


def test_a_sample_too_thin_for_its_interior_says_so_once(caplog):
    """One layer of the cubic lattice (2R thick between the walls) under interior_margin = 0.5
    largest diameters (R) from the floor and the lid: no interior, so the interior fraction and
    the coordination numbers are NaN, and the run is told why once, not a silent NaN a plot
    shows as nothing."""
    scene = _scene(16, 8 * R, 8 * R, 2 * R, BOTH)
    _place(scene, _cubic()[::4])  # the 16 centres at z = R
    with caplog.at_level("WARNING", logger="sphere.observables"):
        first, second = _sample(scene), _sample(scene)
    for obs in (first, second):
        assert obs["packing_fraction"] == pytest.approx(math.pi / 6, rel=1e-12)
        for name in (
            "packing_fraction_interior",
            "coordination",
            "coordination_no_rattlers",
            "rattler_fraction",
        ):
            assert math.isnan(obs[name]), name
    warned = [r.getMessage() for r in caplog.records if r.name == "sphere.observables"]
    assert len(warned) == 1 and "0.002 m thick along z" in warned[0] and "interior_margin = 0.5" in warned[0]


def test_resting_column_stress_is_its_weight():
    """Three spheres resting in a column on the floor: the contact virial gives, with
    compression positive, sigma_zz V = sum_i m_i g (z_i - z_floor) (virial theorem for a body in
    equilibrium under gravity and the floor's reaction; the overlaps, ~ 3 m g/k_n = 1e-8 m, shift
    it by ~ 1e-5), no horizontal stress, and the layer profile carries the weight above."""
    scene = _scene(3, 10 * R, 10 * R, 20 * R, '[[walls]]\nface = "z-"', layers=3, g=-9.81, e=0.1)
    _place(scene, np.array([[5 * R, 5 * R, z * R] for z in (1.0, 3.0, 5.0)]))
    p = scene.state.particles
    p.vel[...] = 0.0
    advance(scene, int(0.02 / scene.state.clock.dt))
    obs = _sample(scene)
    sigma = obs["stress"]
    volume = (10 * R) ** 2 * (p.pos[:, 2].max() + R)
    m, g = p.mass[0], 9.81
    expected = float(np.sum(p.mass * g * p.pos[:, 2])) / volume
    assert sigma[2, 2] == pytest.approx(expected, rel=1e-4)
    assert abs(sigma[0, 0]) < 1e-6 * expected and abs(sigma[0, 2]) < 1e-6 * expected
    assert obs["pressure"] == pytest.approx(expected / 3, rel=1e-4)
    # per layer (one sphere each, layer volume A dz): sphere k carries its own weight and those above
    dz = (p.pos[:, 2].max() + R) / 3
    for k in range(3):
        # moment of sphere k: bottom contact at z_k - R with force (3 - k) m g, top one at z_k + R
        # with -(2 - k) m g: (R (3 - k) + R (2 - k)) m g
        assert obs["stress_profile"][k, 2, 2] == pytest.approx(
            R * (5 - 2 * k) * m * g / ((10 * R) ** 2 * dz), rel=1e-4
        )


def test_gas_stress_is_kinetic_about_the_layer_mean():
    """Two spheres flying apart along x without contacts: sigma_xx = sum m v'^2 / V with v' the
    velocity about the layer's mean; moving together, no stress at all."""
    scene = _scene(2, 10 * R, 10 * R, 10 * R, BOTH)
    _place(scene, np.array([[2 * R, 5 * R, 5 * R], [8 * R, 5 * R, 5 * R]]))
    p = scene.state.particles
    p.vel[...] = [[-0.3, 0.0, 0.0], [0.3, 0.0, 0.0]]
    sigma = _sample(scene)["stress"]
    assert sigma[0, 0] == pytest.approx(2 * p.mass[0] * 0.09 / (10 * R) ** 3, rel=1e-12)
    assert np.count_nonzero(sigma) == 1
    p.vel[...] = [[0.3, 0.1, 0.0], [0.3, 0.1, 0.0]]
    assert np.all(_sample(scene)["stress"] == 0.0)
