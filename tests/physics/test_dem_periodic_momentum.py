"""Periodic boundaries and momentum conservation of the DEM contact forces.

Sources: Newton's third law for pair forces (the contact kernel computes each pair once, with
operations antisymmetric in (i, j), and applies it to both, kernels/contact.py), and the translation
invariance of a periodic box (Allen & Tildesley, Computer Simulation of Liquids, 2nd ed.,
section 1.5.2: minimum-image convention): a collision straddling a periodic face must be the
same collision as one in the middle of the box.
"""

from __future__ import annotations

import math

import numpy as np
from dem_physics_cases import advance, clamped_contact_time, make_scene, sphere_mass

from sphere_cli.physics.neighbors import spring_rows
from sphere_cli.physics.observe.energy import observables

R = 1.0e-3  # m
DENSITY = 2500.0  # kg/m^3
MASS = sphere_mass(R, DENSITY)
EPS = np.finfo(float).eps


def _momentum(p) -> np.ndarray:
    return (p.mass[:, None] * p.vel).sum(axis=0)


def _oblique_pair(tmp_path, centre, box, drift, skin, name):
    """Two spheres closing on each other along an oblique normal n (not along any axis), with a
    relative tangential velocity (a tangential spring builds up) and a common drift velocity.
    The touch is at `centre`, 3.5 steps after the start."""
    kn, e, mu = 1.0e3, 0.8, 1.0
    dt = clamped_contact_time(kn, 0.5 * MASS, e) / 50
    n = np.array([1.0, 0.5, 0.2])
    n /= np.linalg.norm(n)
    t = np.cross(n, [0.0, 0.0, 1.0])
    t /= np.linalg.norm(t)
    v_rel, w_rel = 0.2, 0.05
    gap = v_rel * 3.5 * dt
    pos = np.array([centre - (R + 0.5 * gap) * n, centre + (R + 0.5 * gap) * n])
    pos = np.mod(pos, box)  # into the box [0, L)
    vel = np.array([drift + 0.5 * (v_rel * n + w_rel * t), drift - 0.5 * (v_rel * n + w_rel * t)])
    return make_scene(
        tmp_path,
        pos,
        R,
        vel,
        kn=kn,
        e=e,
        mu=mu,
        dt=dt,
        upper=(box, box, box),
        periodic=(True, True, True),
        skin=skin,
        name=name,
    )


def test_collision_across_periodic_faces_equals_one_at_rest_inside(tmp_path):
    """A collision whose contact point sits on the x and y periodic faces, the pair drifting
    fast enough that both spheres wrap across faces and the neighbour list is rebuilt several
    times while they touch, evolves exactly like the same collision at rest in the middle of the
    box with a skin so wide that its list is never rebuilt (Galilean invariance, and the schema's
    promise that the skin affects speed only). So the contact is kept at every step (count and
    tangential history), relative positions, velocities, spins and the tangential spring agree
    to round-off, every position stays wrapped in [0, L), and total momentum is conserved to
    round-off.

    Round-off: the runs differ in the rounding of coordinates of size up to L = 10 R and of
    velocities carrying a drift of ~4 m/s; over ~150 steps that is ~N eps (L, 4 m/s), about
    1e-13 R and 1e-13 m/s; 1e-10 R and 1e-10 m/s allow 1000x that, and are 1e6 times below the
    effect of a single lost history step (dt w_rel ~ 2e-7 m ~ 2e-4 R).
    """
    box = 10.0 * R
    drift = np.array([3.0, 2.0, 0.5])  # m/s: 0.7 mm (0.7 R) while the contact lasts
    still = _oblique_pair(tmp_path, np.array([0.5, 0.5, 0.5]) * box, box, np.zeros(3), 2.0, "still.csv")
    moving = _oblique_pair(tmp_path, np.array([1.0, 1.0, 0.5]) * box, box, drift, 0.4, "moving.csv")
    pa, pb = still.state.particles, moving.state.particles
    p0 = _momentum(pb)
    still_builds = still.state.neighbors.builds
    wraps_in_contact = 0
    rebuilds_in_contact = 0
    contact_steps = 0
    largest_spring = 0.0
    for _ in range(150):
        before = pb.pos.copy()
        builds = moving.state.neighbors.builds
        advance(still, 1)
        advance(moving, 1)
        in_contact = observables(moving)["contacts"]
        assert in_contact == observables(still)["contacts"]
        if in_contact:
            contact_steps += 1
            wraps_in_contact += int(np.any(np.abs(pb.pos - before) > 0.5 * box))
            rebuilds_in_contact += moving.state.neighbors.builds - builds
            largest_spring = max(largest_spring, float(np.abs(moving.state.neighbors.hist[0]).max()))
        d_still = pa.pos[0] - pa.pos[1]
        d_moving = pb.pos[0] - pb.pos[1]
        d_moving -= box * np.round(d_moving / box)
        np.testing.assert_allclose(d_moving, d_still, rtol=0, atol=1e-10 * R)
        np.testing.assert_allclose(pb.vel - drift, pa.vel, rtol=0, atol=1e-10)
        np.testing.assert_allclose(pb.angvel * R, pa.angvel * R, rtol=0, atol=1e-10)
        np.testing.assert_allclose(
            spring_rows(moving.state.neighbors)[:, 0],
            spring_rows(still.state.neighbors)[:, 0],
            rtol=0,
            atol=1e-10 * R,
        )
        assert np.all((pb.pos >= 0.0) & (pb.pos < box))
        np.testing.assert_allclose(_momentum(pb), p0, rtol=0, atol=1e-14 * np.abs(p0).max())
    assert still.state.neighbors.builds == still_builds  # the reference never rebuilt its list
    # the scenario did what it is meant to: one contiguous contact, crossing faces and rebuilds
    assert 40 <= contact_steps <= 60
    assert wraps_in_contact >= 1 and rebuilds_in_contact >= 1
    assert largest_spring > 1e-3 * R
    # the spheres separated again and the pair is no longer in contact
    assert observables(moving)["contacts"] == 0


def test_single_sphere_crosses_periodic_faces_unchanged(tmp_path):
    """A sphere that crosses periodic faces (x up, y down, z up) keeps its velocity bitwise and
    sits at x0 + v t wrapped into the box (round-off: N eps L with N ~ 1000 steps, 1e-12 L)."""
    box = 10.0 * R
    pos = np.array([[0.9, 0.1, 0.5], [0.3, 0.6, 0.2]]) * box  # the second one crosses z only
    vel = np.array([[2.0, -1.5, 1.0], [0.0, 0.0, 3.0]])
    scene = make_scene(
        tmp_path,
        pos,
        R,
        vel,
        kn=1.0e3,
        upper=(box, box, box),
        periodic=(True, True, True),
        gravity=(0.0, 0.0, 0.0),
    )
    p = scene.state.particles
    steps = math.ceil(0.6 * box / scene.state.clock.dt)  # the slowest crossing: 0.5 box at 1 m/s
    advance(scene, steps)
    t = scene.state.clock.time
    crossings = np.floor((pos + vel * t) / box)  # faces crossed along each axis (signed)
    assert np.all(crossings[0] != 0) and crossings[1, 2] != 0
    np.testing.assert_array_equal(p.vel, vel)
    expected = np.mod(pos + vel * t, box)
    diff = p.pos - expected
    diff -= box * np.round(diff / box)  # a coordinate right at a face may sit at 0 or L
    np.testing.assert_allclose(diff, 0.0, atol=1e-12 * box)
    assert np.all((p.pos >= 0.0) & (p.pos < box))


def test_pair_forces_are_equal_and_opposite(tmp_path):
    """Newton's third law, bitwise: in a collision of two spheres of different radii, with spin
    and oblique approach (normal, tangential and damping forces all active), the force on one is
    exactly minus the force on the other at every step. The tangential force acts at the contact
    point, so the torques are -r_i n x F_t on both: T_i/r_i = T_j/r_j (to a few ulps: the radii
    multiply a common, bitwise-equal cross product)."""
    kn, e, mu = 1.0e3, 0.5, 0.4
    r = np.array([1.0e-3, 0.7e-3])
    m_eff = 1.0 / (1.0 / sphere_mass(r[0], DENSITY) + 1.0 / sphere_mass(r[1], DENSITY))
    dt = clamped_contact_time(kn, m_eff, e) / 50
    n = np.array([0.3, -1.0, 0.4])
    n /= np.linalg.norm(n)
    c = np.array([0.05, 0.05, 0.05])
    gap = 1e-6
    pos = [c - (r[0] + 0.5 * gap) * n, c + (r[1] + 0.5 * gap) * n]
    vel = [0.1 * n + [0.05, 0.0, 0.02], -0.1 * n + [0.0, 0.03, 0.0]]
    scene = make_scene(tmp_path, pos, r, vel, kn=kn, e=e, mu=mu, dt=dt)
    p = scene.state.particles
    p.angvel[:] = [[100.0, -50.0, 30.0], [-20.0, 0.0, 80.0]]  # no contact yet: forces unaffected
    touching = 0
    largest_torque = 0.0
    for _ in range(200):
        advance(scene, 1)
        touching += int(np.any(p.force[0] != 0.0))
        largest_torque = max(largest_torque, float(np.abs(p.torque).max()))
        np.testing.assert_array_equal(p.force[0], -p.force[1])
        np.testing.assert_allclose(
            p.torque[0] / r[0],
            p.torque[1] / r[1],
            rtol=4 * EPS,
            atol=4 * EPS * np.abs(p.torque[0] / r[0]).max(),
        )
    assert touching > 40
    assert largest_torque > 0.0


def test_momentum_conserved_in_a_colliding_cloud(tmp_path):
    """Total linear momentum of a polydisperse cloud colliding in a fully periodic box (no
    gravity, no walls) is conserved to round-off.

    Every pair force is summed into both particles as exact negatives, so sum_i F_i vanishes up
    to the rounding of each particle's own sum (a few eps |F|). Over N = 2000 steps the drift is
    at most ~ N eps sum |m v| = 4e-13 of the momentum scale; the bound 1e-12 keeps a 2x margin
    and is far below the momentum exchanged in collisions (the kinetic energy drops by 10s of %).
    """
    rng = np.random.default_rng(7)
    box, count = 12.0 * R, 80
    radius = rng.uniform(0.6 * R, R, count)
    k = np.arange(count)
    spacing = box / 5.0
    sites = np.stack([k % 5, (k // 5) % 5, k // 25], axis=1) * spacing + 0.5 * spacing
    pos = sites + rng.uniform(-0.1, 0.1, (count, 3)) * spacing
    vel = rng.normal(0.0, 0.3, (count, 3)) + [0.2, -0.1, 0.05]  # a net drift as well
    scene = make_scene(
        tmp_path,
        pos,
        radius,
        vel,
        kn=1.0e3,
        e=0.7,
        mu=0.5,
        upper=(box, box, box),
        periodic=(True, True, True),
    )
    p = scene.state.particles
    p0 = _momentum(p)
    scale = float((p.mass[:, None] * np.abs(p.vel)).sum())
    energy0 = observables(scene)["kinetic_energy"]
    contacts = 0
    for _ in range(40):
        advance(scene, 50)
        contacts += observables(scene)["contacts"]
        np.testing.assert_allclose(_momentum(p), p0, rtol=0, atol=1e-12 * scale)
    assert contacts >= 20  # many collisions happened
    assert observables(scene)["kinetic_energy"] < 0.9 * energy0
