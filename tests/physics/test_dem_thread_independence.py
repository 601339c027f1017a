"""Results do not depend on the number of threads (deterministic
parallelism, gather not scatter; reproducible runs and bitwise restarts depend on it).

A few hundred polydisperse spheres thrown down into a walled box, friction and damping on, run with
1 and with 2 Numba threads: every prognostic array must be bitwise equal (np.array_equal, no
tolerance: any race or thread-dependent summation order shows up as a last-bit difference that
grows chaotically in a dense granular flow).
"""

from __future__ import annotations

import numba
import numpy as np
import pytest

from sphere_cli.api import run_in_memory
from sphere_cli.kernels.laws import HERTZ_MINDLIN
from sphere_cli.simulation import advance

CASE = """
[simulation]
duration = 1.0
dt = "auto"

[domain]
lower = [0.0, 0.0, 0.0]
upper = [0.012, 0.012, 0.03]
gravity = [0.0, 0.0, -9.81]

[particles]
count = 300
density = 2500.0
seed = 3
velocity = [0.1, -0.05, -0.5]
radius = { distribution = "uniform", min = 0.0007, max = 0.001 }
placement = { method = "lattice", spacing = 1.05, jitter = 0.5 }

[contact]
model = "linear"
normal_stiffness = 1.0e3
restitution = 0.5
friction = 0.5

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
"""

# The same pour with Hertz-Mindlin contacts, two materials mixed at random, a pair table, a wall
# of a material, and rolling resistance: every branch of the contact kernels.
HERTZ_CASE = (
    CASE.replace(
        """[contact]
model = "linear"
normal_stiffness = 1.0e3
restitution = 0.5
friction = 0.5
""",
        """[contact]
model = "hertz-mindlin"
restitution = 0.5
friction = 0.5
rolling_friction = 0.05

[[contact.pairs]]
materials = ["soft", "hard"]
friction = 0.3

[[materials]]
name = "soft"
density = 1200.0
youngs_modulus = 1.0e7
poisson_ratio = 0.4

[[materials]]
name = "hard"
density = 2500.0
youngs_modulus = 5.0e7
poisson_ratio = 0.25
restitution = 0.8
""",
    )
    .replace("density = 2500.0\nseed = 3", "material = { soft = 0.5, hard = 0.5 }\nseed = 3")
    .replace('[[walls]]\nface = "z-"', '[[walls]]\nface = "z-"\nmaterial = "hard"')
)

STEPS = {"linear": 3400, "hertz": 3000}


def _run(case: str, steps: int, threads: int):
    numba.set_num_threads(threads)
    scene = run_in_memory(case, 0)
    advance(scene, steps)
    return scene


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs at least 2 Numba threads")
@pytest.mark.parametrize("law", ["linear", "hertz"])
def test_settling_is_bitwise_independent_of_thread_count(law):
    """Same scene, 1 vs 2 threads: positions, velocities, spins, forces and the tangential
    history (pairs and walls) bitwise equal after 3400 steps of pouring (linear: about 70 pair
    and 10 wall contacts at the end, 28 list rebuilds), or 3000 (Hertz-Mindlin mixture with
    rolling resistance: about 40 pair and 12 wall contacts at the end, 11 rebuilds)."""
    case = CASE if law == "linear" else HERTZ_CASE
    assert law == "linear" or "hertz-mindlin" in case and "material = " in case
    previous = numba.get_num_threads()
    try:
        one = _run(case, STEPS[law], 1)
        two = _run(case, STEPS[law], 2)
    finally:
        numba.set_num_threads(previous)
    p1, p2 = one.state.particles, two.state.particles
    assert one.state.clock.step == two.state.clock.step == STEPS[law]
    # the scene is a real test: many contacts, some sticking with loaded springs, several rebuilds
    from sphere_cli.physics.observe.energy import observables

    obs = observables(one)
    if law == "linear":
        assert obs["contacts"] >= 40 and obs["wall_contacts"] >= 10
    else:
        assert obs["contacts"] >= 20 and obs["wall_contacts"] >= 4
    assert one.state.neighbors.builds >= 3
    assert np.abs(one.state.neighbors.hist).max() > 0.0
    if law == "hertz":
        assert one.contact.law_code == HERTZ_MINDLIN and one.contact.rolling and set(p1.material) == {0, 1}
        assert np.abs(p1.angvel).max() > 0.0
    for name in ("pos", "vel", "angvel", "force", "torque"):
        assert np.array_equal(getattr(p1, name), getattr(p2, name)), name
    n1, n2 = one.state.neighbors, two.state.neighbors
    assert np.array_equal(n1.nbr_count, n2.nbr_count)
    assert np.array_equal(n1.nbr, n2.nbr)
    assert np.array_equal(n1.hist, n2.hist)
    assert np.array_equal(one.state.walls.hist, two.state.walls.hist)
