"""The vans1d fluid coupled to the particles.

Static immersed bed: 96 glass beads settle in still water on a floor; at rest each one's contact
and wall forces balance its weight and its buoyancy, so the floor carries the buoyant weight
sum (m_p - rho_f V_p) g of the whole bed. Tolerance 1 %; the residual motion of the
settled bed is measured and far below it.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from sphere_cli.config.load import parse_case
from sphere_cli.scene.builder import build_scene
from sphere_cli.simulation import advance

STILL_BED = """
[simulation]
duration = 1.0
dt = "auto"
[domain]
upper = [0.03, 0.03, 0.05]
periodic = [true, true, false]
gravity = [0.0, 0.0, -9.81]
[particles]
count = 96
density = 2500.0
seed = 5
radius = { distribution = "uniform", min = 0.00285, max = 0.00315 }
placement = { method = "lattice", spacing = 1.02, region_upper = [0.03, 0.03, 0.04] }
[contact]
normal_stiffness = 5.0e3
restitution = 0.2
friction = 0.4
[[walls]]
face = "z-"
[fluid]
model = "vans1d"
surface = 0.045
cells = 45
flow = { kind = "solved", initial = "rest" }
"""


def floor_force(scene) -> np.ndarray:
    """Total force of the floor on the particles [N] (the walls' own measurement: minus the
    force the particles put on the wall)."""
    scene.walls.measure(scene.state)
    return -scene.state.walls.force[0]


def test_static_immersed_bed_floor_carries_the_buoyant_weight():
    """The lattice collapses into a random bed, which comes to rest (kinetic energy below 1e-8 J,
    rms velocity about 3e-4 m/s) between 0.5 and 0.6 s depending on the realisation (the last
    bits of the arithmetic change it); once at rest, the floor force equals the buoyant weight to
    1e-5 (measured)."""
    scene = build_scene(parse_case(STILL_BED))
    state = scene.state
    p = state.particles
    chunk = round(0.05 / state.clock.dt)
    advance(scene, round(0.4 / state.clock.dt))
    while 0.5 * float(np.sum(p.mass[:, None] * p.vel**2)) >= 1e-8 and state.clock.time < 1.0:
        advance(scene, chunk)
    kinetic = 0.5 * float(np.sum(p.mass[:, None] * p.vel**2))
    weight = float(np.sum(p.mass)) * 9.81
    buoyant_weight = float(np.sum(p.mass - 1000.0 * 4.0 / 3.0 * math.pi * p.radius**3)) * 9.81
    assert kinetic < 1e-8  # J: at rest within 1 s
    assert floor_force(scene)[2] == pytest.approx(buoyant_weight, rel=0.01)
    assert abs(floor_force(scene)[2] - weight) > 0.3 * weight  # the buoyancy is not negligible


ONE_WAY = """
[simulation]
duration = 1.0
dt = 1.0e-5
stability = "contact"
[domain]
upper = [0.006, 0.006, 0.02]
periodic = [true, true, false]
gravity = [0.0, 0.0, -9.81]
[particles]
count = 2
density = 2500.0
radius = { distribution = "fixed", value = 0.001 }
placement = { method = "lattice", spacing = 1.2, region_lower = [0.0, 0.0, 0.008] }
[contact]
normal_stiffness = 1.0e4
[fluid]
model = "vans1d"
surface = 0.02
cells = 40
coupling = { interval = 1.0e-4 }
flow = { kind = "log-law", friction_velocity = 0.05, bed_level = 0.002, roughness_length = 1.0e-4 }
"""


def test_prescribed_log_law_is_one_way():
    """A log-law flow is set at the layer centres, u = (u*/kappa) ln((z - z_b)/z0) (0 below
    z_b + z0), and stays as given while particles move through it; they are dragged along x."""
    scene = build_scene(parse_case(ONE_WAY))
    column = scene.state.fluid.column
    z = column.centres
    expected = 0.05 / 0.41 * np.log(np.maximum(z - 0.002, 1e-4) / 1e-4)
    np.testing.assert_allclose(column.u, expected, rtol=1e-14)
    before = column.u.copy()
    advance(scene, 300)
    assert np.array_equal(column.u, before)
    p = scene.state.particles
    assert np.all(p.vel[:, 0] > 0.0)


def test_only_the_selected_materials_feel_the_fluid():
    """fluid.materials = ["glass"]: in a uniform 0.5 m/s stream the glass beads are dragged
    along x and buoyed, the steel ones (not selected) fall as in vacuum. (The materials table
    lists steel first, particles.material glass first: ids follow particles.material.)"""
    text = ONE_WAY.replace(
        'flow = { kind = "log-law", friction_velocity = 0.05, bed_level = 0.002, roughness_length = 1.0e-4 }',
        'flow = { kind = "profile", z = [0.0, 0.02], u = [0.5, 0.5] }\nmaterials = ["glass"]',
    ).replace("count = 2\ndensity = 2500.0", "count = 8\nmaterial = { glass = 0.5, steel = 0.5 }")
    text = text.replace(
        "[fluid]",
        '[[materials]]\nname = "steel"\ndensity = 7800.0\n'
        '[[materials]]\nname = "glass"\ndensity = 2500.0\n[fluid]',
    )
    text = text.replace("region_lower = [0.0, 0.0, 0.008]", "region_lower = [0.0, 0.0, 0.004]")
    scene = build_scene(parse_case(text))
    p = scene.state.particles
    steps = 200
    advance(scene, steps)
    glass, steel = p.material == 0, p.material == 1
    assert glass.sum() == steel.sum() == 4
    assert np.all(p.vel[glass, 0] > 0.0)
    assert np.all(p.vel[steel, 0] == 0.0)
    np.testing.assert_allclose(p.vel[steel, 2], -9.81 * steps * 1.0e-5, rtol=1e-12)
    assert np.all(p.vel[glass, 2] > -9.81 * steps * 1.0e-5 * (1 - 1000 / 2500) * 1.0001)


ROUGH_BED = """
[simulation]
duration = 1.0
dt = 1.0e-5
stability = "contact"
[domain]
upper = [0.012, 0.012, 0.02]
periodic = [true, true, false]
gravity = [0.5, 0.0, -9.8]
[particles]
density = 2500.0
placement = {{ method = "file", path = "rough.csv" }}
[contact]
normal_stiffness = 1.0e4
[fluid]
model = "vans1d"
surface = 0.02
cells = 40
flow = {{ kind = "solved", initial = "steady", mixing_length = "{mixing}" }}
"""


def rough_bed(tmp_path, fixed: int, mixing: str = "prandtl"):
    """A square layer of 16 touching spheres of radius 1.5 mm on the floor (centres at z = 1.5 mm)
    under a slope-driven flow; `fixed` = 1: held in place (the rough bed), 0: free."""
    r = 1.5e-3
    rows = ["x,y,z,r,fixed"]
    for i in range(4):
        rows += [f"{(2 * i + 1) * r!r},{(2 * j + 1) * r!r},{r!r},{r!r},{fixed}" for j in range(4)]
    (tmp_path / "rough.csv").write_text("\n".join(rows) + "\n")
    return build_scene(parse_case(ROUGH_BED.format(mixing=mixing), tmp_path / "case.toml"))


def test_a_fixed_rough_bed_is_seen_by_the_fluid(tmp_path):
    """Fixed spheres (zero inverse mass) are in the solid profiles the fluid sees, as in YADE's
    HydroForceEngine (they were left out, so a fixed rough layer had solid fraction 0): the
    layer through their centres holds their exact slice volume (pi/4 of its area at the centre
    plane, less over the layer's 0.5 mm), the fluid takes their drag, and the steady flow is
    slowed there exactly as over the same layer of free spheres at rest. The fixed spheres receive
    no force from the fluid."""
    fixed = rough_bed(tmp_path, 1)
    free = rough_bed(tmp_path, 0)
    r, dz = 1.5e-3, 0.5e-3
    k = 2  # layer [1.0, 1.5] mm
    slice_fraction = math.pi * (r * r * dz - ((0.0) ** 3 - (-dz) ** 3) / 3) / ((2 * r) ** 2 * dz)
    for scene in (fixed, free):
        prof = scene.state.fluid.profiles
        assert prof.solid_fraction[k] == pytest.approx(slice_fraction, rel=1e-12)
        assert prof.exchange_coefficient[k] > 0.0
    np.testing.assert_array_equal(fixed.state.fluid.column.u, free.state.fluid.column.u)
    u = fixed.state.fluid.column.u
    assert u[k] < 0.5 * u[8]  # slowed inside the layer against just above it (z = 4.25 mm)
    advance(fixed, 10)
    assert np.all(fixed.state.particles.vel == 0.0)


def test_only_the_particles_of_the_id_range_feel_the_fluid():
    """fluid.ids = [2, 5] (YADE's ids): in a uniform 0.5 m/s stream particles 2..5 are dragged
    along x and buoyed; the others fall as in vacuum."""
    text = ONE_WAY.replace(
        'flow = { kind = "log-law", friction_velocity = 0.05, bed_level = 0.002, roughness_length = 1.0e-4 }',
        'flow = { kind = "profile", z = [0.0, 0.02], u = [0.5, 0.5] }\nids = [2, 5]',
    ).replace("count = 2\n", "count = 8\n")
    text = text.replace("region_lower = [0.0, 0.0, 0.008]", "region_lower = [0.0, 0.0, 0.004]")
    scene = build_scene(parse_case(text))
    p = scene.state.particles
    steps = 200
    advance(scene, steps)
    inside = (np.arange(8) >= 2) & (np.arange(8) <= 5)
    assert np.all(p.vel[inside, 0] > 0.0)
    assert np.all(p.vel[~inside, 0] == 0.0)
    np.testing.assert_allclose(p.vel[~inside, 2], -9.81 * steps * 1.0e-5, rtol=1e-12)
