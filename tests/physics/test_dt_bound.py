"""The stability bound for spheres held by several contacts (physics/contact.stability_limit,
user guide section 2): stacks, a wedged sphere and a dense packing stay bounded in energy for
1e5 steps at 0.95 x the bound; dt = "auto" stays below it and a given dt 5 % above it is refused,
naming it; and the bound is no larger than 2 over the fastest mode of a contact network computed
from its stiffness matrix."""

from __future__ import annotations

import math

import numpy as np
import pytest
from dem_physics_cases import advance, make_scene

from sphere_cli.errors import CaseError
from sphere_cli.physics.contact import coordination_bound, damped_limit, stability_limit
from sphere_cli.physics.observe.energy import observables

R = 1e-3
G = (0.0, 0.0, -9.81)
STEPS = 100_000


def _at(tmp_path, pos, radius, factor: float, **kw):
    """The scene with dt = factor x the stability bound that dt = "auto" reports for it."""
    bound = make_scene(tmp_path, pos, radius, **kw).dt_bound
    return make_scene(tmp_path, pos, radius, dt=factor * bound, **kw), bound


def _assert_bounded(scene, steps: int = STEPS) -> None:
    """Energy never grows beyond the start's (plus 1 % of the potential-energy scale for the
    integrator's bounded oscillation about the conserved one), and nothing blows up."""
    p = scene.state.particles
    height = scene.case.domain.upper[2] - scene.case.domain.lower[2]
    scale = float(np.sum(p.mass) * 9.81 * height)
    start = observables(scene)["total_energy"]
    for _ in range(10):
        advance(scene, steps // 10)
        assert np.all(np.isfinite(p.pos)) and np.all(np.isfinite(p.vel))
        assert observables(scene)["total_energy"] <= start + 0.01 * scale


@pytest.mark.parametrize("e", [0.9, 0.5])
def test_a_column_of_five_spheres_on_a_floor_at_095_of_the_bound(tmp_path, e):
    pos = [[0.005, 0.005, R * (1 + 2 * k) - 1e-6 * k] for k in range(5)]
    scene, _ = _at(tmp_path, pos, R, 0.95, e=e, kn=1e4, walls=["z-"], gravity=G, upper=(0.01, 0.01, 0.02))
    _assert_bounded(scene)
    assert scene.state.particles.pos[:, 2].max() < 0.01  # the column still stands


def test_two_stacked_spheres_that_were_thrown_apart_at_09_of_the_old_limit(tmp_path):
    pos = [[0.005, 0.005, R], [0.005, 0.005, 3 * R]]
    scene, _ = _at(tmp_path, pos, R, 0.95, e=0.5, kn=1e4, walls=["z-"], gravity=G, upper=(0.01, 0.01, 0.02))
    _assert_bounded(scene)


def test_a_small_sphere_wedged_between_two_large_ones(tmp_path):
    small = 0.3e-3
    lift = math.sqrt((R + small) ** 2 - R**2)  # touching both large spheres
    pos = [[0.004, 0.005, R], [0.006, 0.005, R], [0.005, 0.005, R + lift]]
    radius = [R, R, small]
    scene, _ = _at(
        tmp_path,
        pos,
        radius,
        0.95,
        e=0.9,
        kn=1e4,
        walls=["z-", "x-", "x+"],
        gravity=G,
        upper=(0.01, 0.01, 0.01),
    )
    _assert_bounded(scene)
    p = scene.state.particles
    assert p.pos[2, 2] > R  # still wedged above the floor between them


def test_a_dense_frictionless_packing(tmp_path):
    """64 spheres of 1.0-1.1 mm on a lattice of 2.1 mm, pressed together in a closed box, no
    friction, slight damping."""
    rng = np.random.default_rng(7)
    side = 4
    grid = np.array([[i, j, k] for i in range(side) for j in range(side) for k in range(side)], dtype=float)
    radius = rng.uniform(1.0e-3, 1.1e-3, grid.shape[0])
    pos = (grid + 0.5) * 2.1e-3 + rng.uniform(-1e-5, 1e-5, grid.shape)
    box = side * 2.1e-3
    walls = ["x-", "x+", "y-", "y+", "z-", "z+"]
    scene, _ = _at(
        tmp_path,
        pos,
        radius,
        0.95,
        e=0.95,
        mu=0.0,
        kn=1e4,
        walls=walls,
        gravity=G,
        upper=(box, box, box),
        overlap_tolerance=0.15,
    )
    advance(scene, 1)
    assert observables(scene)["contacts"] >= 60  # pressed together: many contacts at once
    _assert_bounded(scene)


def test_auto_stays_below_the_bound_and_a_step_above_it_is_refused_naming_it(tmp_path):
    pos = [[0.005, 0.005, R * (1 + 2 * k)] for k in range(3)]
    kw = dict(kn=1e4, walls=["z-"], upper=(0.01, 0.01, 0.02))
    auto = make_scene(tmp_path, pos, R, **kw)
    assert auto.state.clock.dt <= 0.9 * auto.dt_bound < auto.dt_limit
    make_scene(tmp_path, pos, R, dt=0.99 * auto.dt_bound, **kw)  # accepted
    with pytest.raises(CaseError) as refused:
        make_scene(tmp_path, pos, R, dt=1.05 * auto.dt_bound, **kw)
    message = str(refused.value)
    assert "simulation.dt" in message and f"above the stability bound {auto.dt_bound:.4g} s" in message
    assert "held by up to" in message and 'stability = "contact"' in message
    # a scene that never packs densely may run up to the limit of one contact, and no further
    make_scene(tmp_path, pos, R, dt=1.05 * auto.dt_bound, stability="contact", **kw)
    with pytest.raises(CaseError) as refused:
        make_scene(tmp_path, pos, R, dt=1.05 * auto.dt_limit, stability="contact", **kw)
    assert f"above the stability limit {auto.dt_limit:.4g} s" in str(refused.value)


def _fastest_mode(pos, radius, mass, pairs, walls, kn, kt):
    """omega_max [1/s] of the linear contact network: contacts (i, j) and (i, wall normal) with
    springs k_n along the normal and k_t across it at the contact point, every sphere free to
    move and turn (I = 0.4 m r^2); the largest eigenvalue of M^-1/2 K M^-1/2."""
    n = len(mass)
    inertia = 0.4 * np.asarray(mass) * np.asarray(radius) ** 2
    weights = np.repeat(np.stack([mass, inertia], axis=1), 3, axis=1).reshape(-1)
    k = np.zeros((6 * n, 6 * n))

    def cross(r):
        return np.array([[0, -r[2], r[1]], [r[2], 0, -r[0]], [-r[1], r[0], 0]])

    def add(rows, stiffness):
        k[...] += stiffness * np.outer(rows, rows)

    for contact in pairs + walls:
        i = contact[0]
        if contact in pairs:
            j = contact[1]
            normal = (pos[j] - pos[i]) / np.linalg.norm(pos[j] - pos[i])
        else:
            j, normal = None, np.asarray(contact[1], dtype=float)
        basis = np.linalg.svd(normal[None, :])[2]  # the normal and two tangents
        for axis, stiffness in ((basis[0], kn), (basis[1], kt), (basis[2], kt)):
            rows = np.zeros(6 * n)
            # velocity of i's contact point along `axis`: v_i + w_i x (r_i n)
            rows[6 * i : 6 * i + 3] = axis
            rows[6 * i + 3 : 6 * i + 6] = -axis @ cross(radius[i] * normal)
            if j is not None:
                rows[6 * j : 6 * j + 3] = -axis
                rows[6 * j + 3 : 6 * j + 6] = -axis @ cross(radius[j] * normal)
            add(rows, stiffness)
    scaled = k / np.sqrt(np.outer(weights, weights))
    return math.sqrt(np.linalg.eigvalsh(scaled).max())


@pytest.mark.parametrize("shape", ["chain", "fcc", "wedge"])
def test_the_bound_holds_the_fastest_mode_of_a_contact_network(tmp_path, shape):
    """Undamped linear contacts: 2/omega_max of the actual network >= the bound. The bound takes
    12 contacts per sphere; taken with the chain's 2 (omega^2 = 2 kappa/m* = 4 k_n/m) it is
    the limit of a long chain of equal spheres held at both ends, nearly reached."""
    kn, kt = 1e4, 1e4 / 3.5
    if shape == "chain":
        count = 40
        pos = np.array([[2 * R * k, 0.0, 0.0] for k in range(count)])
        radius = np.full(count, R)
        pairs = [(k, k + 1) for k in range(count - 1)]
        walls = [(0, (-1.0, 0.0, 0.0)), (count - 1, (1.0, 0.0, 0.0))]
    elif shape == "fcc":  # a sphere and its 12 neighbours, and theirs among themselves
        shell = [[a, b, 0] for a in (-1, 1) for b in (-1, 1)]
        shell += [[a, 0, b] for a in (-1, 1) for b in (-1, 1)] + [[0, a, b] for a in (-1, 1) for b in (-1, 1)]
        pos = np.array([[0.0, 0.0, 0.0]] + shell) * math.sqrt(2) * R
        radius = np.full(len(pos), R)
        pairs = [
            (i, j)
            for i in range(len(pos))
            for j in range(i + 1, len(pos))
            if np.linalg.norm(pos[i] - pos[j]) < 2 * R * 1.0001
        ]
        walls = []
    else:  # a small sphere on two large ones on a floor
        small = 0.3 * R
        lift = math.sqrt((R + small) ** 2 - R**2)
        pos = np.array([[-R, 0, R], [R, 0, R], [0, 0, R + lift]])
        radius = np.array([R, R, small])
        pairs = [(0, 2), (1, 2), (0, 1)]
        walls = [(0, (0.0, 0.0, -1.0)), (1, (0.0, 0.0, -1.0))]
    mass = 2500.0 * 4.0 / 3.0 * math.pi * radius**3
    omega = _fastest_mode(pos, radius, mass, pairs, walls, kn, kt)
    scene = make_scene(
        tmp_path,
        pos + 0.02,
        radius,
        kn=kn,
        kt=kt,
        e=1.0,
        walls=["x-"] if walls else [],
        upper=(0.2, 0.2, 0.2),
        overlap_tolerance=0.5,
    )
    p = scene.state.particles
    bound, _ = stability_limit(scene.tables, p.radius, p.mass, p.material, 0.0, ["x-"] if walls else [])
    assert bound <= 2.0 / omega * (1 + 1e-12)
    if shape == "chain":
        per_two = bound * math.sqrt(12 / 2)
        assert 0.99 * 2.0 / omega < per_two <= 2.0 / omega * (1 + 1e-12)


def test_coordination_and_the_damped_limit():
    assert coordination_bound(1.0, 1.0, 100) == 12  # the kissing number
    assert coordination_bound(1.0, 1.0, 3) == 3  # no more bodies than there are
    assert coordination_bound(10.0, 1.0, 10**6) >= 400  # small ones around a large one
    # one undamped mode: 2/omega; critically damped relative to the scheme: omega dt = f(zeta)
    assert damped_limit(4.0, 0.0) == pytest.approx(1.0)
    zeta, omega = 0.3, 5.0
    f = 2 * (math.sqrt(1 + 4 * zeta**2) - 2 * zeta)
    assert damped_limit(omega**2, 2 * zeta * omega) == pytest.approx(f / omega, rel=1e-12)


def test_a_wall_moved_faster_than_a_tenth_of_the_smallest_radius_a_step_limits_dt(tmp_path):
    """configs/direct-shear.toml with its shear at 1e3 m/s instead of 0.1 (a unit typed wrong):
    the run went on at the contacts' dt, the wall crossing 10^3 of a radius a step, until the
    particles it dragged tripped the run's check. Now the wall's speed caps the step: "auto"
    takes at most the step in which it covers 0.1 of the smallest radius, a given dt above that
    is refused naming the wall's key; at 0.1 m/s the contacts still set it."""
    from pathlib import Path

    from sphere_cli.config.load import parse_case
    from sphere_cli.scene.builder import build_scene

    text = (Path(__file__).parents[2] / "configs" / "direct-shear.toml").read_text()
    assert text.count("shear_velocity = 0.1 ") == 1
    fast = text.replace("shear_velocity = 0.1 ", "shear_velocity = 1e3 ")
    as_given = build_scene(parse_case(text, tmp_path / "case.toml"))
    assert "wall" not in as_given.dt_limit_reason
    scene = build_scene(parse_case(fast, tmp_path / "case.toml"))
    smallest = float(scene.state.particles.radius.min())
    assert scene.dt_limit == pytest.approx(0.1 * smallest / 1e3, rel=1e-12)
    assert "stages[2].walls[0].shear_velocity = 1000 m/s" in scene.dt_limit_reason
    assert scene.state.clock.dt == scene.dt_limit  # the most a step may be: no safety share of it
    given = fast.replace('dt = "auto"', f"dt = {2 * scene.dt_limit!r}", 1)
    assert given != fast
    with pytest.raises(
        CaseError,
        match=r"simulation\.dt = .*longer than the .* s in which the z\+ wall, moved at .*= 1000 m/s",
    ):
        build_scene(parse_case(given, tmp_path / "case.toml"))
