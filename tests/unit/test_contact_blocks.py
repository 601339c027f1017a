"""The pair and wall kernels evaluate the contact law in blocks of touching pairs (kernels/contact.py):
a block fills up in the middle of a row, a row can hold more contacts than a block, rows wait
for their pairs across chunks. None of this may change a result: the forces, torques and
springs must be bitwise those of a plain contact-by-contact sweep (written here in Python with
the law's own functions, which Numba compiles without reordering any floating-point
operation), for any number of chunks. The same for the walls (kernels/walls.py), whose blocks
hold whole particles, so a particle's wall contacts are summed in one go.

The scene: a large sphere (index 0, so its half row lists every neighbour) wrapped in a shell
of 200 small spheres that press into it, among 300 touching pairs of small spheres in a periodic
box, moving and spinning at random, two materials, run for a few steps so that springs exist and
some slide.
"""

from __future__ import annotations

import dataclasses
import math
import textwrap

import numpy as np
import pytest

from sphere_cli.config.load import parse_case
from sphere_cli.kernels import contact as sweep
from sphere_cli.kernels import laws as law
from sphere_cli.kernels.neighbors import drop_ghost_pairs, minimum_image
from sphere_cli.physics.contact import rows_across_chunks
from sphere_cli.physics.neighbors import listed_slots, spring_rows
from sphere_cli.scene.builder import build_scene
from sphere_cli.simulation import advance

BIG = 2.0e-3
SMALL = 2.5e-4
SHELL = 200
LOOSE = 600
BOX = 0.012
HERTZ_MATERIALS = """
        [[materials]]
        name = "a"
        density = 2500.0
        youngs_modulus = 1.0e6
        poisson_ratio = 0.3
        [[materials]]
        name = "b"
        density = 7800.0
        youngs_modulus = 5.0e6
        poisson_ratio = 0.25
"""


def _particle_file(path) -> None:
    rng = np.random.default_rng(7)
    centre = np.full(3, 0.5 * BOX)
    k = np.arange(SHELL) + 0.5  # Fibonacci sphere: even spacing, no two shell spheres touching
    polar = np.arccos(1.0 - 2.0 * k / SHELL)
    azimuth = math.pi * (1.0 + 5.0**0.5) * k
    normal = np.stack(
        [np.sin(polar) * np.cos(azimuth), np.sin(polar) * np.sin(azimuth), np.cos(polar)], axis=1
    )
    shell = centre + (BIG + SMALL * 0.97) * normal  # 3 % of a small radius into the big one
    loose = []
    while len(loose) < LOOSE:  # touching pairs away from the big sphere, apart from each other
        p = rng.uniform(2.0 * SMALL, BOX - 2.0 * SMALL, 3)
        q = rng.normal(size=3)
        q = p + 1.96 * SMALL * q / np.linalg.norm(q)
        if min(np.linalg.norm(p - centre), np.linalg.norm(q - centre)) < BIG + 3.0 * SMALL:
            continue
        if (
            loose
            and np.min(np.linalg.norm(np.array(loose)[:, None, :] - np.array([p, q]), axis=2)) < 2.05 * SMALL
        ):
            continue
        loose += [p, q]
    pos = np.concatenate([centre[None, :], shell, np.array(loose)])
    radius = np.concatenate([[BIG], np.full(SHELL + LOOSE, SMALL)])
    vel = rng.normal(0.0, 0.05, pos.shape)
    vel[1 : SHELL + 1] -= 0.2 * normal  # the shell moves in: overlaps grow, springs load
    rows = ["x,y,z,r,vx,vy,vz"] + [
        ",".join(repr(float(v)) for v in (*p, r, *u)) for p, r, u in zip(pos, radius, vel, strict=True)
    ]
    path.write_text("\n".join(rows) + "\n")


def _case(path, hertz: bool) -> str:
    contact = (
        """
        model = "hertz-mindlin"
        restitution = 0.4
        friction = 0.15
        rolling_friction = 0.1
        """
        if hertz
        else """
        model = "linear"
        normal_stiffness = 50.0
        restitution = 0.4
        friction = 0.15
        """
    )
    materials = (
        HERTZ_MATERIALS
        if hertz
        else """
        [[materials]]
        name = "a"
        density = 2500.0
        [[materials]]
        name = "b"
        density = 7800.0
        normal_stiffness = 200.0
        """
    )
    return textwrap.dedent(
        f"""
        [simulation]
        duration = 1.0
        dt = 2.0e-6
        stability = "contact"
        [domain]
        upper = [{BOX}, {BOX}, {BOX}]
        periodic = [true, true, true]
        gravity = [0.0, 0.0, -9.81]
        [particles]
        material = {{ a = 0.5, b = 0.5 }}
        overlap_tolerance = 0.2
        placement = {{ method = "file", path = "{path}" }}
        [contact]
        {textwrap.dedent(contact)}
        {textwrap.dedent(materials)}
        """
    )


def _reference(state, table, code: int, rolling: bool, spring_dt: float, step_dt: float):
    """(force, torque, springs) by a plain sweep in ascending i, each row in ascending j."""
    p, box, nl = state.particles, state.box, state.neighbors
    length, periodic = box.length, box.periodic
    pos, vel, angvel, vel_pred, angvel_pred = p.pos, p.vel, p.angvel, p.vel_pred, p.angvel_pred
    force = p.mass[:, None] * box.body_acc[None, :]
    torque = np.zeros_like(force)
    hist = spring_rows(nl)
    for i in range(p.count):
        ri = p.radius[i]
        for k in range(min(nl.nbr_count[i], nl.nbr.shape[1])):
            j = nl.nbr[i, k]
            rj = p.radius[j]
            d = [minimum_image(pos[i, a] - pos[j, a], length[a], periodic[a]) for a in range(3)]
            dist2 = d[0] * d[0] + d[1] * d[1] + d[2] * d[2]
            if dist2 >= (ri + rj) * (ri + rj):
                hist[i, k] = 0.0
                continue
            kn, kt, dn, dt, mu, mu_r = table[p.material[i], p.material[j]]
            dist = math.sqrt(dist2)
            inv = 1.0 / dist
            n = [d[0] * inv, d[1] * inv, d[2] * inv]
            delta = (ri + rj) - dist

            def slip(v, w, n=n, i=i, j=j, ri=ri, rj=rj):
                s = [ri * w[i, a] + rj * w[j, a] for a in range(3)]
                a = [v[i, b] - v[j, b] for b in range(3)]
                return [
                    a[0] - (s[1] * n[2] - s[2] * n[1]),
                    a[1] - (s[2] * n[0] - s[0] * n[2]),
                    a[2] - (s[0] * n[1] - s[1] * n[0]),
                ]

            v = slip(vel, angvel)
            vn = v[0] * n[0] + v[1] * n[1] + v[2] * n[2]
            u = slip(vel_pred, angvel_pred)
            un = u[0] * n[0] + u[1] * n[1] + u[2] * n[2]
            root_m = math.sqrt(law.reduced(p.inv_mass[i], p.inv_mass[j]))
            r_eff = ri * rj / (ri + rj) if code == law.HERTZ_MINDLIN or rolling else 0.0
            travel, grow, end = law.contact_window(delta, vn, un, step_dt)
            fn, kt_now, ct = law.normal_law(kn, kt, dn, dt, code, delta, r_eff, root_m, un, travel, grow)
            g0, g1, g2, x0, x1, x2 = law.tangential_spring(
                *hist[i, k], *(v[a] - vn * n[a] for a in range(3)), *n, kt_now, ct, mu, fn, spring_dt * grow,
                *(u[a] - un * n[a] for a in range(3)), end,
            )  # fmt: skip
            hist[i, k] = (x0, x1, x2)
            e = (fn * n[0] + g0, fn * n[1] + g1, fn * n[2] + g2)
            c = (n[1] * g2 - n[2] * g1, n[2] * g0 - n[0] * g2, n[0] * g1 - n[1] * g0)
            m = (0.0, 0.0, 0.0)
            if rolling and mu_r > 0.0:
                m = law.rolling_torque(
                    *(angvel[i, a] - angvel[j, a] for a in range(3)), *n, mu_r, r_eff, fn,
                    law.reduced(p.inv_inertia[i], p.inv_inertia[j]), step_dt,
                )  # fmt: skip
            for a in range(3):
                force[i, a] += e[a]
                torque[i, a] -= ri * c[a]
                force[j, a] -= e[a]
                torque[j, a] -= rj * c[a]
                if rolling:
                    torque[i, a] += m[a]
                    torque[j, a] -= m[a]
    return force, torque, hist


def _kernels(scene, bounds: np.ndarray, spring_dt: float, warm: bool = False):
    """(force, torque, springs) of the block kernels with the particles cut at `bounds`, the
    partners prefetched or not (`warm`)."""
    state, contact = scene.state, scene.contact
    p, box, nl = state.particles, state.box, state.neighbors
    chunks = bounds.size - 1
    hist = nl.hist.copy()
    force = np.zeros_like(p.force)
    torque = np.zeros_like(p.torque)
    slots = np.zeros((hist.shape[0], contact.width))
    blocks = np.zeros((chunks, sweep.FIELDS * sweep.BLOCK))
    block_ids = np.zeros((chunks, sweep.ID_ROWS * sweep.BLOCK), dtype=np.uint64)
    block_rows = np.zeros((chunks, 2 * sweep.BLOCK), dtype=np.int64)
    pair_row = np.zeros(nl.start[-1], dtype=np.int32)
    pair_partner = np.zeros_like(pair_row)
    sweep.pack_pairs(nl.nbr, nl.nbr_count, nl.start, pair_row, pair_partner)
    common = (
        p.pos, p.vel, p.angvel, p.vel_pred, p.angvel_pred, p.radius, p.inv_mass, p.inv_inertia, p.material,
        nl.nbr, nl.nbr_count, nl.start, hist, contact.table, contact.law_code, contact.rolling, box.length,
        box.periodic, spring_dt, state.clock.dt,
    )  # fmt: skip
    if chunks > 1:
        rows, cuts = rows_across_chunks(nl.nbr, nl.nbr_count, bounds, chunks)
        sweep.cross_chunk_pairs(*common, rows, cuts, slots, blocks, block_ids)
    sweep.chunk_pair_forces(
        *common,
        nl.rev,
        nl.rev_count,
        pair_row,
        pair_partner,
        warm,
        box.body_acc,
        p.mass,
        bounds,
        slots,
        blocks,
        block_ids,
        block_rows,
        force,
        torque,
    )
    return force, torque, spring_rows(dataclasses.replace(nl, hist=hist))


@pytest.fixture(scope="module", params=[False, True], ids=["linear", "hertz-rolling"])
def scene(request, tmp_path_factory):
    folder = tmp_path_factory.mktemp("blocks")
    _particle_file(folder / "particles.csv")
    scene = build_scene(parse_case(_case(folder / "particles.csv", request.param)))
    advance(scene, 20)
    return scene


def test_the_scene_exercises_every_path_of_the_blocks(scene):
    nl = scene.state.neighbors
    assert nl.nbr_count[0] > 3 * sweep.BLOCK, "the big sphere's row must span several blocks"
    force, torque, hist = _kernels(scene, np.array([0, scene.state.particles.count]), scene.state.clock.dt)
    touching = np.any(hist != 0.0, axis=2)
    assert touching.sum() > 4 * sweep.BLOCK
    assert scene.contact.rolling == (scene.contact.law_code == law.HERTZ_MINDLIN)
    assert len(set(scene.state.particles.material.tolist())) == 2


@pytest.mark.parametrize("spring_dt", [0.0, 2.0e-6], ids=["initial", "step"])
def test_blocks_reproduce_a_contact_by_contact_sweep_bitwise(scene, spring_dt):
    state, contact = scene.state, scene.contact
    expected = _reference(state, contact.table, contact.law_code, contact.rolling, spring_dt, state.clock.dt)
    n = state.particles.count
    # one chunk; cuts inside the shell, where the rows wait for pairs across chunks, and many
    for bounds in ([0, n], [0, 120, n], [0, 1, 300, 301, 700, n], list(np.linspace(0, n, 12).astype(int))):
        for warm in (False, True):  # the partners prefetched or not: the same operations
            got = _kernels(scene, np.array(bounds, dtype=np.int64), spring_dt, warm)
            for name, a, b in zip(("force", "torque", "springs"), got, expected, strict=True):
                assert np.array_equal(a, b), f"{name} differs with chunks cut at {bounds}, warm {warm}"


def _listed_pairs(nl) -> tuple[np.ndarray, np.ndarray]:
    """(rows, partners) of the listed pairs in the springs' packed order, by NumPy."""
    rows = np.repeat(np.arange(nl.nbr.shape[0]), np.minimum(nl.nbr_count, nl.nbr.shape[1]))
    return rows, nl.nbr[listed_slots(nl.nbr, nl.nbr_count)]


def test_the_springs_of_listed_pairs_come_apart_are_cleared(scene):
    """A pair the list still holds but that no longer touches loses its spring (a new contact
    starts from none): the sweep clears it without a branch per pair, so every other spring,
    and the forces, must come out as the reference's."""
    state, contact = scene.state, scene.contact
    nl = state.neighbors
    kept = nl.hist.copy()
    p, box = state.particles, state.box
    n = p.count
    rows, partners = _listed_pairs(nl)
    d = p.pos[rows] - p.pos[partners]
    d -= box.length * np.round(d / box.length) * box.periodic
    apart = np.einsum("ij,ij->i", d, d) >= (p.radius[rows] + p.radius[partners]) ** 2
    assert 100 < np.count_nonzero(apart) < apart.size - 100
    stale = np.random.default_rng(3).normal(0.0, 1.0e-6, (np.count_nonzero(apart), 3))
    stale[::7, 1:] = 0.0  # one component set is enough
    nl.hist[: nl.start[-1]][apart] = stale
    try:
        expected = _reference(state, contact.table, contact.law_code, contact.rolling, 0.0, state.clock.dt)
        for bounds in ([0, n], [0, 1, 300, 301, 700, n]):
            got = _kernels(scene, np.array(bounds, dtype=np.int64), 0.0)
            for name, a, b in zip(("force", "torque", "springs"), got, expected, strict=True):
                assert np.array_equal(a, b), f"{name} differs with chunks cut at {bounds}"
            assert not np.any(got[2][listed_slots(nl.nbr, nl.nbr_count)][apart])
    finally:
        nl.hist[...] = kept


def test_the_packed_pairs_follow_every_change_of_the_list(scene):
    """The sweep takes each listed pair's row and partner from arrays in the springs' order
    (physics/contact.py `_pairs`): they must be those of the list as it is at every call, after
    a build and after a rank drops its ghosts' pairs in place (kernels/neighbors.py
    drop_ghost_pairs: the same arrays, the same build, other row starts)."""
    contact, nl = scene.contact, scene.state.neighbors
    kept = {name: getattr(nl, name).copy() for name in ("nbr", "nbr_count", "start", "hist")}

    def packed_now():
        args = contact.kernel_arguments(scene.state)[1]
        rows, listed = _listed_pairs(nl)
        pairs = int(nl.start[-1])
        assert args[22] is contact.pair_row and args[23] is contact.pair_partner
        return np.array_equal(contact.pair_row[:pairs], rows) and np.array_equal(
            contact.pair_partner[:pairs], listed
        )

    try:
        assert packed_now()
        owned = np.zeros(nl.nbr.shape[0], dtype=np.bool_)
        owned[::3] = True  # the pairs of two particles of the other two thirds go
        drop_ghost_pairs(owned, nl.nbr, nl.nbr_count, nl.start, nl.hist, True)
        assert packed_now()
        scene.neighbors.rebuild(scene.state)
        assert packed_now()
    finally:
        for name, array in kept.items():
            setattr(nl, name, array)
        scene.neighbors.rebuild(scene.state)


def test_the_partners_are_prefetched_only_on_a_state_beyond_half_its_share_of_the_cache(scene, monkeypatch):
    """physics/contact.py beyond_cache: the sweep prefetches each listed pair's partner only
    where the state a step goes through outgrows half the largest cache, shared between the MPI
    ranks of a node (measured: 20 000 spheres 0-7 % slower with the hints, 50 000 5-10 % faster,
    two processes of 50 000 sharing a cache 20 % faster each)."""
    import types

    from sphere_cli.physics import contact as module

    state = scene.state
    p = state.particles
    for sharing in (1, 3):
        world = None if sharing == 1 else types.SimpleNamespace(node_size=sharing)
        monkeypatch.setattr(module.ranks, "current", lambda world=world: world)
        for below in (1, 0):
            scene.neighbors.rebuild(state)  # asked once a list (the arrays' sizes change with it only)
            nl = state.neighbors
            arrays = [getattr(p, name) for name in p.PROGNOSTIC] + [p.vel_pred, p.angvel_pred]
            arrays += [nl.nbr, nl.nbr_count, nl.start, nl.hist, nl.ref_pos]
            held = sum(a.nbytes for a in arrays)
            cache, beyond = 2 * sharing * (held - below), below == 1
            monkeypatch.setattr(module, "last_level_cache_bytes", lambda cache=cache: cache)
            assert module.beyond_cache(state) is beyond, (sharing, below)
            assert scene.contact.kernel_arguments(state)[1][24] is beyond


def test_the_largest_cache_is_read_from_the_systems_description(tmp_path):
    """runtime.cache_sizes and last_level_cache_bytes: the data caches by level, the highest
    level's size (Linux's sysfs layout), or the default where there is none to read."""
    from sphere_cli.runtime import DEFAULT_CACHE_BYTES, cache_sizes, last_level_cache_bytes

    caches = [("Data", "1", "32K"), ("Instruction", "1", "64K"), ("Unified", "2", "1024K")]
    caches.append(("Unified", "3", "32768K"))
    for index, (kind, level, size) in enumerate(caches):
        folder = tmp_path / "cache" / f"index{index}"
        folder.mkdir(parents=True)
        (folder / "type").write_text(f"{kind}\n")
        (folder / "level").write_text(f"{level}\n")
        (folder / "size").write_text(f"{size}\n")
    assert cache_sizes(str(tmp_path / "cache")) == {"L1": "32K", "L2": "1024K", "L3": "32768K"}  # data only
    assert last_level_cache_bytes(str(tmp_path / "cache")) == 32 * 1024**2
    (tmp_path / "cache" / "index3" / "size").write_text("2M\n")
    assert last_level_cache_bytes(str(tmp_path / "cache")) == 32 * 1024**2  # read once
    last_level_cache_bytes.cache_clear()
    assert last_level_cache_bytes(str(tmp_path / "cache")) == 2 * 1024**2
    assert last_level_cache_bytes(str(tmp_path / "none")) == DEFAULT_CACHE_BYTES
    last_level_cache_bytes.cache_clear()


def _walled_case(folder) -> str:
    """A 6 mm box with walls on every face, each face covered by a 6 x 6 layer of spheres that
    press 3 % of their radius into it (edge and corner spheres touch two or three walls), moving
    and spinning at random; Hertz-Mindlin, rolling resistance, two materials."""
    rng = np.random.default_rng(11)
    r = 4.0e-4
    side = 0.006
    grid = np.linspace(1.5 * r, side - 1.5 * r, 6)
    u, v = (a.ravel() for a in np.meshgrid(grid, grid, indexing="ij"))
    pos = []
    for axis in range(3):
        for coord in (0.97 * r, side - 0.97 * r):
            layer = np.empty((u.size, 3))
            layer[:, axis] = coord
            layer[:, (axis + 1) % 3] = u
            layer[:, (axis + 2) % 3] = v
            pos.append(layer)
    pos = np.concatenate(pos)
    keep = np.ones(len(pos), dtype=bool)  # drop the duplicates of neighbouring faces at the edges
    for k in range(len(pos)):
        if keep[k] and np.any(np.linalg.norm(pos[k + 1 :] - pos[k], axis=1)[keep[k + 1 :]] < 2.1 * r):
            keep[k] = False
    pos = pos[keep]
    vel = rng.normal(0.0, 0.05, pos.shape)
    rows = ["x,y,z,vx,vy,vz"] + [
        ",".join(repr(float(x)) for x in (*a, *b)) for a, b in zip(pos, vel, strict=True)
    ]
    (folder / "walled.csv").write_text("\n".join(rows) + "\n")
    walls = "".join(f'[[walls]]\nface = "{f}"\n' for f in ("x-", "x+", "y-", "y+", "z-", "z+"))
    return (
        textwrap.dedent(
            f"""
        [simulation]
        duration = 1.0
        dt = 2.0e-6
        stability = "contact"
        [domain]
        upper = [{side}, {side}, {side}]
        gravity = [0.0, 0.0, -9.81]
        [particles]
        material = {{ a = 0.5, b = 0.5 }}
        radius = {{ distribution = "fixed", value = {r} }}
        placement = {{ method = "file", path = "{folder / "walled.csv"}" }}
        [contact]
        model = "hertz-mindlin"
        restitution = 0.4
        friction = 0.15
        rolling_friction = 0.1
        """
        )
        + textwrap.dedent(HERTZ_MATERIALS)
        + walls
    )


def test_wall_blocks_reproduce_a_contact_by_contact_loop_bitwise(tmp_path):
    scene = build_scene(parse_case(_walled_case(tmp_path)))
    advance(scene, 20)
    state, walls = scene.state, scene.walls
    p, w = state.particles, state.walls
    code, rolling, dt = scene.contact.law_code, scene.contact.rolling, state.clock.dt
    expected_f = np.zeros_like(p.force)
    expected_t = np.zeros_like(p.torque)
    expected_h = w.hist.copy()
    contacts = 0
    for i in range(p.count):
        ri = p.radius[i]
        f = [0.0, 0.0, 0.0]
        t = [0.0, 0.0, 0.0]
        for k in range(len(w.faces)):
            a = w.axis[k]
            gap = w.sign[k] * (p.pos[i, a] - w.coord[k])
            if gap >= ri:
                expected_h[i, k] = 0.0
                continue
            contacts += 1
            kn, kt, dn, dtt, mu, mu_r = w.table[k, p.material[i]]
            n = [w.sign[k] if a == b else 0.0 for b in range(3)]

            def slip(v, om, vw, n=n, i=i, ri=ri):
                s = [ri * om[i, b] for b in range(3)]
                return [
                    (v[i, 0] - vw[0]) - (s[1] * n[2] - s[2] * n[1]),
                    (v[i, 1] - vw[1]) - (s[2] * n[0] - s[0] * n[2]),
                    (v[i, 2] - vw[2]) - (s[0] * n[1] - s[1] * n[0]),
                ]

            v = slip(p.vel, p.angvel, w.vel[k])
            vn = v[0] * n[0] + v[1] * n[1] + v[2] * n[2]
            u = slip(p.vel_pred, p.angvel_pred, w.vel_pred[k])
            un = u[0] * n[0] + u[1] * n[1] + u[2] * n[2]
            travel, grow, end = law.contact_window(ri - gap, vn, un, dt)
            root_m = math.sqrt(p.mass[i])
            fn, kt_now, ct = law.normal_law(kn, kt, dn, dtt, code, ri - gap, ri, root_m, un, travel, grow)
            g0, g1, g2, x0, x1, x2 = law.tangential_spring(
                *expected_h[i, k], *(v[b] - vn * n[b] for b in range(3)), *n, kt_now, ct, mu, fn, dt * grow,
                *(u[b] - un * n[b] for b in range(3)), end,
            )  # fmt: skip
            expected_h[i, k] = (x0, x1, x2)
            g = (g0, g1, g2)
            c = (n[1] * g2 - n[2] * g1, n[2] * g0 - n[0] * g2, n[0] * g1 - n[1] * g0)
            m = (0.0, 0.0, 0.0)
            if rolling and mu_r > 0.0:
                m = law.rolling_torque(*p.angvel[i], *n, mu_r, ri, fn, p.inertia[i], dt)
            for b in range(3):
                f[b] += fn * n[b] + g[b]
                t[b] -= ri * c[b]
                if rolling:
                    t[b] += m[b]
        expected_f[i] = f
        expected_t[i] = t
    assert contacts > 2 * sweep.BLOCK, "the walls' contacts must fill several blocks"
    hist = w.hist.copy()
    for warm in (False, True):  # the particles' lines prefetched or not: the same operations
        scene.contact.warm = warm
        w.hist[...] = hist
        p.force[...] = 0.0
        p.torque[...] = 0.0
        walls.forces(state)
        assert np.array_equal(p.force, expected_f), warm
        assert np.array_equal(p.torque, expected_t), warm
        assert np.array_equal(w.hist, expected_h), warm
