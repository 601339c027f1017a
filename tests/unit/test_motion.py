"""The kick-drift (kernels/motion.py) cuts its particles into runs of KICK_RUN or more, one parallel
region over them; its serial twin takes them as one run. Every particle gets the same operations
either way, so the two must give the same bits: positions wrapped into a periodic box, the
half-kicked velocities and spins, the predicted ones, and the largest displacement since the
list was built (a maximum: exact in any order). With `kick_first` it takes the last step's kick
in the same pass: the bits of `kick` then the kick-drift."""

from __future__ import annotations

import numpy as np
import pytest

from sphere_cli.kernels.motion import KICK_RUN, kick, kick_drift, kick_drift_serial, kick_serial


def _arrays(n: int, seed: int) -> tuple:
    rng = np.random.default_rng(seed)
    lower, length = np.zeros(3), np.array([0.01, 0.02, 0.03])
    pos = rng.uniform(0.0, 1.0, (n, 3)) * length
    pos[::7, 0] = length[0] - 1e-9  # at the periodic face: the drift wraps them
    vel, angvel = rng.normal(0.0, 0.5, (n, 3)), rng.normal(0.0, 50.0, (n, 3))
    force, torque = rng.normal(0.0, 1e-3, (n, 3)), rng.normal(0.0, 1e-7, (n, 3))
    inv_mass, inv_inertia = rng.uniform(1e3, 1e4, n), rng.uniform(1e8, 1e9, n)
    inv_mass[::11], inv_inertia[::11] = 0.0, 0.0  # held in place
    ref_pos = pos + rng.normal(0.0, 1e-5, (n, 3))
    periodic = np.array([1, 0, 1], dtype=np.uint8)
    return (
        pos, vel, angvel, force, torque, inv_mass, inv_inertia, lower, length, periodic, 1e-4,
        np.zeros((n, 3)), np.zeros((n, 3)), ref_pos,
    )  # fmt: skip


@pytest.mark.parametrize("n", [KICK_RUN // 2, 5 * KICK_RUN + 17])
def test_the_runs_of_the_kick_drift_give_the_one_runs_bits(n):
    runs, whole = _arrays(n, 5), _arrays(n, 5)
    worst_runs = kick_drift(*runs, False)
    worst_whole = kick_drift_serial(*whole, False)
    assert worst_runs == worst_whole > 0.0
    for name, a, b in zip(("pos", "vel", "angvel", "vel_pred", "angvel_pred"), runs[:3] + runs[11:13],
                          whole[:3] + whole[11:13], strict=True):  # fmt: skip
        assert np.array_equal(a, b), name
    held = runs[5] == 0.0
    assert np.array_equal(runs[1][held], _arrays(n, 5)[1][held])  # a held particle keeps its velocity
    assert np.all((runs[0][:, 0] >= 0.0) & (runs[0][:, 0] < runs[8][0]))  # wrapped along x


@pytest.mark.parametrize("threads", ["runs", "serial"])
def test_the_kick_taken_with_the_kick_drift_is_the_kick_then_the_kick_drift(threads):
    n = 5 * KICK_RUN + 17
    drift, kicks = (kick_drift, kick) if threads == "runs" else (kick_drift_serial, kick_serial)
    fused, apart = _arrays(n, 7), _arrays(n, 7)
    worst_fused = drift(*fused, True)
    kicks(*apart[1:7], apart[10])
    worst_apart = drift(*apart, False)
    assert worst_fused == worst_apart > 0.0
    for a, b in zip(fused, apart, strict=True):
        if isinstance(a, np.ndarray):
            assert a.tobytes() == b.tobytes()
    drift_only = _arrays(n, 7)
    drift(*drift_only, False)
    assert not np.array_equal(fused[1], drift_only[1])  # the velocities were kicked twice
