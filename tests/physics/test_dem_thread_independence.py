"""Results do not depend on the number of threads (shared/design.md, section 3: deterministic
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

STEPS = 1500


def _run(threads: int):
    numba.set_num_threads(threads)
    scene = run_in_memory(CASE, 0)
    advance(scene, STEPS)
    return scene


@pytest.mark.skipif(numba.config.NUMBA_NUM_THREADS < 2, reason="needs at least 2 Numba threads")
def test_settling_is_bitwise_independent_of_thread_count():
    """Same scene, 1 vs 2 threads: positions, velocities, spins, forces and the tangential
    history (pairs and walls) bitwise equal after 1500 steps of pouring
    (about 70 pair and 15 wall contacts at the end, 28 list rebuilds)."""
    previous = numba.get_num_threads()
    try:
        one = _run(1)
        two = _run(2)
    finally:
        numba.set_num_threads(previous)
    p1, p2 = one.state.particles, two.state.particles
    assert one.state.clock.step == two.state.clock.step == STEPS
    # the scene is a real test: many contacts, some sticking with loaded springs, several rebuilds
    from sphere_cli.physics.energy import observables

    obs = observables(one)
    assert obs["contacts"] >= 40 and obs["wall_contacts"] >= 10
    assert one.state.neighbors.builds >= 3
    assert np.abs(one.state.neighbors.hist).max() > 0.0
    for name in ("pos", "vel", "angvel", "force", "torque"):
        assert np.array_equal(getattr(p1, name), getattr(p2, name)), name
    n1, n2 = one.state.neighbors, two.state.neighbors
    assert np.array_equal(n1.nbr_count, n2.nbr_count)
    assert np.array_equal(n1.nbr, n2.nbr)
    assert np.array_equal(n1.hist, n2.hist)
    assert np.array_equal(one.state.walls.hist, two.state.walls.hist)
