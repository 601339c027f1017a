"""Several materials in one scene: per-pair properties by the mixing rules or an explicit pair table,
walls of a material, stiff mixtures at the automatic time step, and the time-step limit itself.

Sources: the Hertz effective moduli 1/E* = (1-nu_1^2)/E_1 + (1-nu_2^2)/E_2 and the Mindlin
1/G* = (2-nu_1)/G_1 + (2-nu_2)/G_2 (verification group A2; Johnson, Contact Mechanics, 1985,
sections 4.2 and 7.4); the A2 impact formulas; the documented rules of physics/materials.py;
verification group E for the stability limit (dt_crit with the smallest m* and largest k of any
possible pair; Hertz: Rayleigh time) and the stiffness ratio of 1e4.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from dem_physics_cases import advance, hertz_contact, hertz_reference, make_scene, sphere_mass

from sphere_cli.config.schema import Simulation
from sphere_cli.kernels.laws import D_N, D_T, K_N, K_T, MU, MU_R
from sphere_cli.physics.contact import row_limit
from sphere_cli.physics.laws import LAWS
from sphere_cli.physics.laws.hertz_mindlin import rayleigh_time
from sphere_cli.physics.observe.energy import observables
from sphere_cli.physics.restitution import hertz_damping_coefficient, linear_damping_ratio
from sphere_cli.simulation import check_stable

R = 1.0e-3
A = {"name": "a", "density": 2500.0, "youngs_modulus": 1.0e8, "poisson_ratio": 0.2, "restitution": 0.6}
B = {
    "name": "b",
    "density": 7800.0,
    "youngs_modulus": 1.0e9,
    "poisson_ratio": 0.35,
    "restitution": 0.9,
    "friction": 0.1,
    "rolling_friction": 0.02,
}
STEEL = {"name": "steel", "youngs_modulus": 2.0e11, "poisson_ratio": 0.3, "friction": 0.2}


def _e_star(*materials):
    return 1.0 / sum((1.0 - m["poisson_ratio"] ** 2) / m["youngs_modulus"] for m in materials)


def _g_star(*materials):
    return 1.0 / sum(
        (2.0 - m["poisson_ratio"]) * 2.0 * (1.0 + m["poisson_ratio"]) / m["youngs_modulus"] for m in materials
    )


def test_hertz_pair_table_follows_the_mixing_rules(tmp_path):
    """Every row of the per-pair table (and of each wall) holds (4/3) E*, 8 G*, the calibrated
    Tsuji damping c_h sqrt(4 E*/3) and c_h sqrt(16 G*/3), and the arithmetic means of restitution,
    friction and rolling friction; [contact] fills in what a material leaves out; a
    [[contact.pairs]] entry replaces the mixed values; a rigid wall adds no compliance and uses
    the particle's own surface, a steel wall mixes like a particle, walls[].friction wins.
    Exact formulas, so the table must match to 1e-14."""
    contact = hertz_contact(5.0e8, 0.25, 0.5, 0.4, rolling_friction=0.0)
    contact["pairs"] = [{"materials": ["a", "steel"], "restitution": 0.3}]
    scene = make_scene(
        tmp_path,
        [[0.02, 0.05, 0.05], [0.05, 0.05, 0.05], [0.08, 0.05, 0.05]],
        R,
        contact=contact,
        materials=[A, B, STEEL],
        particle_material={"a": 1.0 / 3.0, "b": 2.0 / 3.0},
        walls=["z-", "z+", "x-"],
        wall_material={"z+": "steel", "x-": "steel"},
        wall_friction={"x-": 0.7},
    )
    tables = scene.tables
    assert tables.law.name == "hertz-mindlin" and tables.names == ["a", "b"]
    assert np.sort(scene.state.particles.material).tolist() == [0, 1, 1]  # exact proportions
    a = {**A, "friction": 0.4, "rolling_friction": 0.0}  # [contact] defaults filled in
    b = B
    steel = {**STEEL, "restitution": 0.5, "rolling_friction": 0.0}

    def check(row, e_star, g_star, e, mu, mu_r):
        c_h = hertz_damping_coefficient(e)
        expected = {
            K_N: 4.0 / 3.0 * e_star,
            K_T: 8.0 * g_star,
            D_N: c_h * math.sqrt(4.0 / 3.0 * e_star),
            D_T: c_h * math.sqrt(16.0 / 3.0 * g_star),
            MU: mu,
            MU_R: mu_r,
        }
        for column, value in expected.items():
            assert row[column] == pytest.approx(value, rel=1e-14, abs=1e-300), column

    def mean(key, *ms):
        return sum(m[key] for m in ms) / len(ms)

    for (i, x), (j, y) in [((0, a), (0, a)), ((0, a), (1, b)), ((1, b), (1, b))]:
        for row in (tables.table[i, j], tables.table[j, i]):
            check(
                row,
                _e_star(x, y),
                _g_star(x, y),
                mean("restitution", x, y),
                mean("friction", x, y),
                mean("rolling_friction", x, y),
            )
    for k, x in enumerate((a, b)):
        # z-: rigid, the particle's own surface
        check(
            tables.wall_table[0, k],
            _e_star(x),
            _g_star(x),
            x["restitution"],
            x["friction"],
            x["rolling_friction"],
        )
        # z+: steel, mixed (a-steel restitution from the pair table)
        e_pair = 0.3 if x is a else mean("restitution", x, steel)
        mixed = (e_pair, mean("friction", x, steel), mean("rolling_friction", x, steel))
        check(tables.wall_table[1, k], _e_star(x, steel), _g_star(x, steel), *mixed)
        # x-: steel with its own friction coefficient
        check(tables.wall_table[2, k], _e_star(x, steel), _g_star(x, steel), e_pair, 0.7, mixed[2])
    assert tables.rolling  # b has rolling friction
    masses = scene.state.particles.mass
    assert set(np.round(masses / sphere_mass(R, 1.0), 6)) == {2500.0, 7800.0}


def test_linear_pair_table_follows_the_mixing_rules(tmp_path):
    """Linear law: k_n and k_t of unlike materials are 2 k_a k_b/(k_a + k_b) (two half-contacts
    in series), like pairs keep the material's k, a material's k_t defaults to 2/7 of its own
    k_n, a rigid wall uses the particle material's k; damping 2 zeta(e) sqrt(k) (1e-14)."""
    soft = {"name": "soft", "density": 1000.0, "normal_stiffness": 1.0e3, "restitution": 0.8}
    hard = {"name": "hard", "density": 1000.0, "normal_stiffness": 4.0e3, "tangential_stiffness": 2.0e3}
    contact = {"model": "linear", "restitution": 0.4, "friction": 0.3}
    scene = make_scene(
        tmp_path,
        [[0.02, 0.05, 0.05], [0.05, 0.05, 0.05]],
        R,
        contact=contact,
        materials=[soft, hard],
        particle_material={"soft": 0.5, "hard": 0.5},
        walls=["z-"],
    )
    t = scene.tables.table
    kt_soft = 2.0 / 7.0 * 1.0e3
    expected = {
        (0, 0): (1.0e3, kt_soft, 0.8),
        (1, 1): (4.0e3, 2.0e3, 0.4),
        (0, 1): (2 * 1.0e3 * 4.0e3 / 5.0e3, 2 * kt_soft * 2.0e3 / (kt_soft + 2.0e3), 0.6),
    }
    for (i, j), (kn, kt, e) in expected.items():
        zeta = linear_damping_ratio(e)
        np.testing.assert_allclose(
            t[i, j, [K_N, K_T, D_N, D_T, MU]],
            [kn, kt, 2 * zeta * math.sqrt(kn), 2 * zeta * math.sqrt(kt), 0.3],
            rtol=1e-14,
        )
    np.testing.assert_allclose(scene.tables.wall_table[0, 0, [K_N, K_T]], [1.0e3, kt_soft], rtol=1e-14)
    np.testing.assert_allclose(scene.tables.wall_table[0, 1, [K_N, K_T]], [4.0e3, 2.0e3], rtol=1e-14)


def _head_on(tmp_path, contact, materials, speed, dt, pair_gap=2.0e-5):
    """Two spheres of radius R, one of each material, closing head-on at +-speed; runs until the
    contact ends. Returns (scene, restitution, F_max, delta_max, contact time, steps in contact)."""
    c = 0.05
    scene = make_scene(
        tmp_path,
        [[c - R - pair_gap, c, c], [c + R + pair_gap, c, c]],
        R,
        [[speed, 0.0, 0.0], [-speed, 0.0, 0.0]],
        contact=contact,
        materials=materials,
        particle_material={m["name"]: 0.5 for m in materials},
        dt=dt,
    )
    p = scene.state.particles
    step_dt = scene.state.clock.dt
    forces, overlaps, steps = [], [], 0
    previous = 2.0 * R - (p.pos[1, 0] - p.pos[0, 0])
    t_touch = None
    for _ in range(1_000_000):
        advance(scene, 1)
        delta = 2.0 * R - (p.pos[1, 0] - p.pos[0, 0])
        if delta > 0.0:
            if t_touch is None:  # free flight is exact: interpolate the touch
                t_touch = scene.state.clock.time - step_dt * delta / (delta - previous)
            steps += 1
            forces.append(-p.force[0, 0])
            overlaps.append(delta)
        elif t_touch is not None:
            break
        previous = delta
    t_end = scene.state.clock.time - step_dt * (-delta) / (previous - delta)
    e = (p.vel[1, 0] - p.vel[0, 0]) / (2.0 * speed)
    return scene, e, max(forces), max(overlaps), t_end - t_touch, steps


def test_unlike_hertz_pair_impact_follows_the_effective_moduli(tmp_path):
    """A2 with the mixed effective modulus: materials a and b (E 1e8 and 1e9 Pa, nu 0.2 and 0.35,
    densities 2500 and 7800 kg/m^3) collide head-on elastically; delta_max, F_max and t_c match
    the A2 formulas with 1/E* = sum (1-nu^2)/E and m* of the two masses within 1e-3 at 100 steps
    per contact (the bound argued in test_dem_hertz.test_hertz_elastic_impact)."""
    a = {**A, "restitution": 1.0}
    b = {**B, "restitution": 1.0}
    speed = 0.3
    m_eff = 1.0 / (1.0 / sphere_mass(R, a["density"]) + 1.0 / sphere_mass(R, b["density"]))
    ref = hertz_reference(_e_star(a, b), 0.5 * R, m_eff, 2.0 * speed)
    dt = ref["contact_time"] / 100
    _, e, force, delta, duration, steps = _head_on(
        tmp_path, hertz_contact(1.0, 0.3, 1.0, 0.0), [a, b], speed, dt
    )
    assert steps >= 99
    assert e == pytest.approx(1.0, abs=1e-3)
    assert force == pytest.approx(ref["force_max"], rel=1e-3)
    assert delta == pytest.approx(ref["delta_max"], rel=1e-3)
    assert duration == pytest.approx(ref["contact_time"], rel=1e-3)


@pytest.mark.parametrize("override", [None, 0.3], ids=["mixed", "pair-table"])
def test_unlike_pair_rebounds_at_the_mixed_or_given_restitution(tmp_path, override):
    """A pair of unlike materials (e = 0.6 and 0.9) rebounds at their mean 0.75, or at the
    restitution of its [[contact.pairs]] entry, within 2e-3 at 100 steps per contact (the
    calibration is exact for any pair of masses; the discretisation error at this resolution is
    <= 1e-3, see test_dem_hertz.test_chung_ooi_restitution)."""
    contact = hertz_contact(1.0, 0.3, 0.5, 0.0)
    if override is not None:
        contact["pairs"] = [{"materials": ["b", "a"], "restitution": override}]
    speed = 0.3
    m_eff = 1.0 / (1.0 / sphere_mass(R, A["density"]) + 1.0 / sphere_mass(R, B["density"]))
    dt = hertz_reference(_e_star(A, B), 0.5 * R, m_eff, 2.0 * speed)["contact_time"] / 100
    _, e, *_ = _head_on(tmp_path, contact, [A, B], speed, dt)
    assert e == pytest.approx(0.75 if override is None else override, abs=2e-3)


# ------------------------------------------------------------------- stiffness ratio 1e4

STIFF_PAIRS = {
    "hertz": (
        hertz_contact(1.0e7, 0.3, 0.8, 0.5),
        [
            {"name": "soft", "density": 2500.0},
            {"name": "stiff", "density": 2500.0, "youngs_modulus": 1.0e11, "poisson_ratio": 0.25},
        ],
    ),
    "linear": (
        {"model": "linear", "normal_stiffness": 1.0e2, "restitution": 0.8, "friction": 0.5},
        [
            {"name": "soft", "density": 2500.0},
            {"name": "stiff", "density": 2500.0, "normal_stiffness": 1.0e6},
        ],
    ),
}


@pytest.mark.parametrize("law", list(STIFF_PAIRS))
def test_stiffness_ratio_1e4_pair_rebounds_at_auto_dt(tmp_path, law):
    """verification group E: a soft and a stiff sphere (E or k_n 1e4 apart) collide head-on at the
    automatic dt without blowing up and rebound at the requested e = 0.8 within 1 %.

    With one particle of each, no stiff-stiff contact is possible, so the linear limit is set by
    the mixed pair (k = 2 k_soft k_stiff/(k_soft + k_stiff)): 17 steps per contact, where the
    calibrated e is realised within 0.22 % (measured). Hertz is bound by the Rayleigh time of the
    stiff sphere, far shorter than the soft contact needs: ~2900 steps, e within 1e-5."""
    contact, materials = STIFF_PAIRS[law]
    scene, e, *_ = _head_on(tmp_path, contact, materials, 0.05, "auto")
    safety = Simulation.model_fields["dt_safety"].default
    auto = min(safety * scene.dt_limit, 0.9 * scene.dt_bound)
    assert scene.state.clock.dt == pytest.approx(auto, rel=1e-15)
    if law == "hertz":
        assert "Rayleigh time" in scene.dt_limit_reason and "'stiff'" in scene.dt_limit_reason
    else:
        assert "'soft' with material 'stiff'" in scene.dt_limit_reason
    assert e == pytest.approx(0.8, rel=0.01)


@pytest.mark.parametrize("law", list(STIFF_PAIRS))
def test_stiff_mixture_runs_stably_at_auto_dt(tmp_path, law):
    """verification group E: 27 spheres, soft and stiff (ratio 1e4) mixed at random, thrown at each
    other and at six walls with random velocities of ~0.1 m/s at the automatic dt: no NaN or
    runaway (the stability check of the run loop, every 100 steps), and no energy gained: the
    total energy (kinetic + elastic) never exceeds the initial one by more than 2e-3 of it and
    ends below it (e = 0.8, friction on). Bound: velocity Verlet's energy error inside a contact
    is ~ (omega dt)^2/8 of that contact's energy, 3e-3 at the automatic dt (omega dt ~ 0.16), and
    any one contact holds only part of the total (measured worst: +5e-4 linear, 0 Hertz); a
    blow-up gains orders of magnitude."""
    contact, materials = STIFF_PAIRS[law]
    rng = np.random.default_rng(5)
    side = 3
    spacing = 2.0 * R + 2.0e-5
    grid = np.stack(np.meshgrid(*[np.arange(side)] * 3, indexing="ij"), axis=-1).reshape(-1, 3)
    pos = R + 1.0e-5 + spacing * grid
    vel = rng.uniform(-0.1, 0.1, size=pos.shape)
    box = side * spacing + 2.0e-5
    scene = make_scene(
        tmp_path,
        pos,
        R,
        vel,
        contact=contact,
        materials=materials,
        particle_material={"soft": 0.5, "stiff": 0.5},
        walls=["x-", "x+", "y-", "y+", "z-", "z+"],
        upper=(box, box, box),
    )
    p = scene.state.particles
    assert set(p.material) == {0, 1}
    energy0 = observables(scene)["total_energy"]
    touched = 0
    for _ in range(60):
        advance(scene, 100)
        check_stable(scene)
        obs = observables(scene)
        assert obs["total_energy"] <= energy0 * (1.0 + 2e-3)
        touched = max(touched, obs["contacts"])
    assert touched >= 3  # pairs really collided (stiff ones, and soft ones begun)
    assert observables(scene)["total_energy"] <= energy0


# ------------------------------------------------------------------ the stability limit


def test_hertz_limit_is_the_smallest_over_materials_pairs_and_walls(tmp_path):
    """verification group E: dt_limit is the smallest of the Rayleigh time pi r sqrt(rho/G)/(0.1631
    nu + 0.8766) of the smallest particle of each material and the contact limit of every
    possible pair and particle-wall contact (tangent stiffness at the largest initial overlap);
    a material with a single particle forms no like pair. Checked against an independent
    enumeration of every pair of particles in the scene."""
    radii = [0.8e-3, 1.0e-3, 1.2e-3, 0.9e-3]
    pos = [[0.01 + 0.01 * k, 0.05, 0.05] for k in range(4)]
    contact = hertz_contact(1.0, 0.3, 0.5, 0.5)
    scene = make_scene(
        tmp_path,
        pos,
        radii,
        contact=contact,
        materials=[A, B],
        particle_material={"a": 0.75, "b": 0.25},
        walls=["z-"],
        wall_material={"z-": "b"},
        overlap_tolerance=0.1,
    )
    p, tables = scene.state.particles, scene.tables
    candidates = []
    for a in range(2):
        members = np.flatnonzero(p.material == a)
        mat = tables.materials[a]
        r = p.radius[members].min()
        candidates.append(rayleigh_time(r, mat.density, mat.shear_modulus, mat.poisson_ratio))
    n = p.count
    for i in range(n):
        row = tables.wall_table[0, p.material[i]]
        candidates.append(row_limit(row, LAWS["hertz-mindlin"], p.mass[i], p.radius[i], 0.1 * p.radius[i]))
        for j in range(i + 1, n):
            row = tables.table[p.material[i], p.material[j]]
            m_eff = p.mass[i] * p.mass[j] / (p.mass[i] + p.mass[j])
            r_eff = p.radius[i] * p.radius[j] / (p.radius[i] + p.radius[j])
            delta = 0.1 * min(p.radius[i], p.radius[j])
            candidates.append(row_limit(row, LAWS["hertz-mindlin"], m_eff, r_eff, delta))
    assert scene.dt_limit == pytest.approx(min(candidates), rel=1e-12)
    # the single b particle has no like partner: a b-b pair limit would be tighter still
    single = np.flatnonzero(p.material == 1)
    assert single.size == 1
    i = int(single[0])
    bb = row_limit(
        tables.table[1, 1], LAWS["hertz-mindlin"], 0.5 * p.mass[i], 0.5 * p.radius[i], 0.1 * p.radius[i]
    )
    assert bb < scene.dt_limit
