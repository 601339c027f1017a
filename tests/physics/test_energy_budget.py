"""The energy budget closes: work of gravity (and walls) = Delta(kinetic + elastic) + energy
dissipated by damping, friction and rolling resistance (within 1 %).

Energy conservation of the equations of motion (work-energy theorem, summed over particles and
contacts): every term is accumulated independently by kernels/observe/energy_budget.py from the contact
law, and the kinetic and elastic energies are state functions, so the residual measures only the
time quadrature of the dissipated power (O(dt) relative, ~1e-3 at dt = auto) and any term
missing or mis-booked (a missing friction or rolling term is 10-30 % of the total here).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sphere_cli.api import run_in_memory
from sphere_cli.simulation import advance

CONFIGS = Path(__file__).resolve().parents[2] / "configs"
POUR = """
[simulation]
duration = 1.0
dt_safety = 0.2

[domain]
upper = [0.008, 0.008, 0.03]

[particles]
count = 48
density = 2500.0
seed = 3
radius = {{ distribution = "uniform", min = 0.0008, max = 0.001 }}
placement = {{ method = "lattice", spacing = 1.1, jitter = 0.5 }}
velocity = [0.05, -0.03, 0.0]

[contact]
model = "linear"
normal_stiffness = 1.0e4
restitution = {restitution}
friction = {friction}
rolling_friction = {rolling}

[[walls]]
face = "z-"
[[walls]]
face = "x-"
[[walls]]
face = "x+"
[[walls]]
face = "y-"
[[walls]]
face = "y+"

[output.observables]
quantities = ["energy", "energy_budget"]
"""


def _budget(scene) -> dict[str, float]:
    return {name: value for name, (value, _unit) in scene.budget.observables(scene.state).items()}


@pytest.mark.parametrize(
    ("friction", "rolling", "restitution"),
    [(0.5, 0.05, 0.5), (0.0, 0.0, 0.3)],
    ids=["friction-rolling", "frictionless"],
)
def test_pour_budget_closes(friction, rolling, restitution):
    """A pour into a closed box: gravity's work equals the change of kinetic + elastic energy plus
    what the dashpots, friction and rolling resistance dissipated, within 1 % of the work."""
    scene = run_in_memory(POUR.format(friction=friction, rolling=rolling, restitution=restitution), 0)
    dt = scene.state.clock.dt
    steps = int(0.08 / dt)
    advance(scene, steps)
    b = _budget(scene)
    work = b["work_gravity"] + b["work_walls"]
    dissipated = b["dissipated_damping"] + b["dissipated_friction"] + b["dissipated_rolling"]
    assert b["work_walls"] == 0.0  # fixed walls do no work
    # the pour is well under way: most of the work has been dissipated, not stored
    assert dissipated > 0.5 * work > 0.0
    assert abs(b["energy_balance_residual"]) < 0.01 * work
    assert math.isclose(work - b["energy_change"] - dissipated, b["energy_balance_residual"], rel_tol=1e-9)
    if friction > 0.0:
        # each mechanism matters, so dropping any one of them would break the 1 % balance
        assert b["dissipated_friction"] > 0.02 * work
        assert b["dissipated_rolling"] > 0.02 * work
    else:
        assert b["dissipated_friction"] == 0.0
        assert b["dissipated_rolling"] == 0.0


def test_gravity_work_matches_potential_energy():
    """Gravity's accumulated work m g . v_{n+1/2} dt equals minus the change of potential energy
    (the drift is x_{n+1} - x_n = v_{n+1/2} dt exactly), to round-off."""
    scene = run_in_memory(POUR.format(friction=0.5, rolling=0.0, restitution=0.5), 0)
    from sphere_cli.physics.observe.energy import observables

    before = observables(scene)["potential_energy"]
    advance(scene, 2000)
    after = observables(scene)["potential_energy"]
    assert math.isclose(_budget(scene)["work_gravity"], before - after, rel_tol=1e-9)


def test_direct_shear_budget_closes():
    """configs/direct-shear.toml as it is (deposit, consolidate under a stress-controlled top
    wall, shear at 0.1 m/s between rough walls of glued spheres): over the whole run the work of
    the walls (their contacts and their glued spheres) and of gravity equals Delta(kinetic +
    elastic) + dissipated within 1 % (measured 1e-4)."""
    text = (CONFIGS / "direct-shear.toml").read_text()
    assert text.count("\nquantities = [") == 1  # its observables, with the budget added
    text = text.replace("\nquantities = [", '\nquantities = ["energy_budget", ')
    scene = run_in_memory(text, 0)
    while not scene.finished:
        advance(scene, 5000)
    b = _budget(scene)
    work = b["work_gravity"] + b["work_walls"]
    dissipated = b["dissipated_damping"] + b["dissipated_friction"] + b["dissipated_rolling"]
    assert b["work_walls"] > 0.5 * work > 0.0  # the walls drive this run
    assert b["dissipated_friction"] > 0.2 * work and dissipated > 0.5 * work
    assert abs(b["energy_balance_residual"]) < 0.01 * work


def test_the_terms_are_the_particles_shares_summed_in_order():
    """Each particle's share is booked apart (what travels with it between MPI ranks) and the
    terms are their sums in particle order; a checkpoint of the older kind (the totals alone)
    carries its totals on."""
    text = POUR.format(friction=0.5, rolling=0.05, restitution=0.5)
    scene = run_in_memory(text, 0)
    advance(scene, 300)
    terms = ("work_gravity", "work_walls", "dissipated_damping", "dissipated_friction", "dissipated_rolling")
    booked = scene.budget.booked
    assert booked.shape == (48, 5) and booked[:, 0].all()
    b = _budget(scene)
    assert [b[name] for name in terms] == [sum(booked[:, t].tolist()) for t in range(5)]
    older = run_in_memory(text, 0)
    totals = booked.sum(axis=0)
    reference = scene.budget.prognostic_state(scene.state)["reference"]
    older.budget.restore(older.state, {"totals": totals, "reference": reference})
    assert not older.budget.booked.any()
    assert [_budget(older)[name] for name in terms] == list(totals)


# one sphere sliding on a rough floor (x+ wall for a second wall out of reach), launched upwards
JUMP = """
[simulation]
duration = 1.0

[domain]
upper = [0.01, 0.01, 0.01]

[particles]
density = 2500.0
radius = { distribution = "fixed", value = 0.001 }
placement = { method = "file", path = "one.csv" }
velocity = [0.05, 0.0, 0.0]

[contact]
model = "linear"
normal_stiffness = 1.0e4
restitution = 0.5
friction = 0.5

[[walls]]
face = "z-"
[[walls]]
face = "x+"

[output.observables]
quantities = ["energy_budget"]
"""


def test_a_spring_parting_by_a_jump_beyond_reach_is_booked(tmp_path, monkeypatch):
    """The budget books each particle's walls from the near-wall list's mask (physics/walls.py
    walls_to_book), skipping walls that neither touch it nor hold its spring. A particle that
    leaves a wall's reach in one step (more than the neighbour skin) has its spring cleared when
    the list is made, after the budget kept the last step's springs: its parting spring must
    still be booked, bitwise as booking every wall does."""
    from sphere_cli.config.load import load_case
    from sphere_cli.physics.walls import PlaneWallForces
    from sphere_cli.scene.builder import build_scene

    (tmp_path / "one.csv").write_text("x,y,z\n0.005,0.005,0.00099999\n")  # at rest: m g / k_n = 1e-8 m
    (tmp_path / "case.toml").write_text(JUMP)

    def jump():
        scene = build_scene(load_case(tmp_path / "case.toml"))
        advance(scene, 50)  # sliding: the floor holds a spring
        assert np.any(scene.state.walls.hist[0, 0] != 0.0)
        scene.state.particles.vel[0, 2] = 0.3 * 0.001 / scene.state.clock.dt  # 0.3 R a step up
        advance(scene, 3)
        assert not scene.state.walls.hist[0].any()  # out of reach: its springs cleared
        return scene.budget.booked.copy(), scene.walls.walls_to_book().copy()

    masked, mask = jump()
    assert mask.tolist() == [0]  # the walls are skipped for the particle now
    monkeypatch.setattr(PlaneWallForces, "walls_to_book", lambda self: np.zeros(0, dtype=np.uint64))
    every, _ = jump()  # no mask: every wall booked for every particle
    assert np.array_equal(masked.view(np.uint64), every.view(np.uint64))


def test_the_shares_are_booked_alike_on_one_thread_and_on_two_in_chunks():
    """The booking goes by chunks of particles (kernels/observe/energy_budget.py BOOKING_CHUNK),
    one chunk after another on one thread (the serial twin) and spread over the threads on two:
    600 poured spheres, two chunks and a part, every one of them booked (each falls: its gravity
    share is not 0), contacts in each chunk, bitwise the same on one thread and on two."""
    import numba

    from sphere_cli.kernels.observe.energy_budget import BOOKING_CHUNK

    text = POUR.format(friction=0.5, rolling=0.05, restitution=0.5)
    text = text.replace("count = 48", "count = 600").replace("[0.008, 0.008, 0.03]", "[0.02, 0.02, 0.04]")
    booked = []
    for threads in (1, 2):
        numba.set_num_threads(threads)
        try:
            scene = run_in_memory(text, 0)
            scene.step.compiled = None  # the hooks: the booking called on its own, each step
            advance(scene, 8000)  # the lowest layer reaches the floor, the others fall onto it
        finally:
            numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
        booked.append(scene.budget.booked.copy())
    assert booked[0].shape == (600, 5) and 600 > 2 * BOOKING_CHUNK and 600 % BOOKING_CHUNK
    assert booked[0][:, 0].all()  # every particle's share booked, the last chunk's too
    for first in range(0, 600, BOOKING_CHUNK):  # contacts in every chunk: their damping booked
        assert np.count_nonzero(booked[0][first : first + BOOKING_CHUNK, 2]) > 5
    assert np.array_equal(booked[0].view(np.uint64), booked[1].view(np.uint64))
