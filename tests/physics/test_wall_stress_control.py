"""Stress-controlled walls (physics/walls.py): one run of three chained stages on a small bed,
laterally periodic, between a fixed floor and a top wall.

  deposit  walls fixed, until the kinetic energy is below 1e-9 J;
  load     the top wall approaches the bed and is driven to sigma_0 = 2 kPa;
  sine     sigma(t) = sigma_0 + sigma_a sin(2 pi f t + phi).

Checks (the reference is statics, not a fit):
- At rest the wall's force balance M dV/dt = A sigma - A sigma_c - C V leaves sigma_c = sigma, so
  the contact stress on the top wall must equal the target once the bed is still: within 1 %
  over the last half of the load stage, frame by frame (the acceptance criterion).
- The floor carries the target plus the weight of the bed per area, W/A, within 1 % of the
  target (the bed is at rest and the lateral boundaries are periodic: no wall friction).
- In the sine stage the contact stress follows the forcing. For a bed of stiffness K the wall
  is a damped oscillator, sigma_c/sigma = K/(K - M w^2 + i C w): for w well below the wall's
  frequency the gain is 1 and the lag is C w/K. K is measured from the wall's own motion (stress
  amplitude times area over displacement amplitude); the measured phase must be the forcing's
  less that lag within 0.02 rad, the gain that of the oscillator within 2 %, the mean the target
  within 1 %. (Here, at 25 Hz with the default critical damping, the lag is about 0.23 rad; it
  scales with the frequency.)
"""

from __future__ import annotations

import math

import h5py
import numpy as np
import pytest

from sphere_cli import api
from sphere_cli.config.load import load_case
from sphere_cli.io.checkpoint import list_checkpoints, read_checkpoint
from sphere_cli.kernels.walls import C_DAMPING, C_MASS
from sphere_cli.scene.builder import build_scene

SIGMA = 2000.0
AMPLITUDE = 500.0
FREQUENCY = 25.0
PHASE = 0.7
LOAD = 0.04
PERIODS = 2

CASE = f"""
[simulation]
duration = 1.0
threads = 1
[domain]
upper = [0.008, 0.008, 0.016]
periodic = [true, true, false]
[particles]
count = 80
density = 2500.0
seed = 3
radius = {{ distribution = "uniform", min = 0.0008, max = 0.001 }}
placement = {{ method = "lattice", spacing = 1.0, jitter = 0.3 }}
[contact]
model = "linear"
normal_stiffness = 1.0e3
restitution = 0.3
friction = 0.5
[[walls]]
face = "z-"
[[walls]]
face = "z+"
[[stages]]
name = "deposit"
duration = 0.3
stop_when = {{ kinetic_energy_below = 1e-9, min_time = 0.02 }}
check_every = 200
[[stages]]
name = "load"
duration = {LOAD}
[[stages.walls]]
face = "z+"
mode = "stress"
stress = {SIGMA}
approach = true
[[stages]]
name = "sine"
duration = {PERIODS / FREQUENCY}
[[stages.walls]]
face = "z+"
mode = "stress"
stress = {SIGMA}
stress_amplitude = {AMPLITUDE}
frequency = {FREQUENCY}
phase = {PHASE}
[output.frames]
every_steps = 160
[output.checkpoints]
every_time = 1.0
"""


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    root = tmp_path_factory.mktemp("stress")
    case = root / "case.toml"
    case.write_text(CASE)
    result = api.run(case, root / "run")
    scene = build_scene(load_case(case))
    # the checkpoint written as the sine stage began holds its wall modes
    sine_start = read_checkpoint(list_checkpoints(root / "run" / "checkpoints")[-2])
    sine_scene = build_scene(load_case(case), restart=sine_start)
    assert sine_scene.stages.index == 2
    with h5py.File(root / "run" / "trajectory.h5", "r") as f:
        obs = f["observables"]
        data = {name: obs[name]["value"][...] for name in obs}
        data["time"] = obs["stage/time"][...]
    data["weight"] = float(np.sum(scene.state.particles.mass) * 9.81)
    data["area"] = 0.008 * 0.008
    data["dt"] = scene.state.clock.dt
    data["mass"] = float(sine_scene.state.walls.control[1, C_MASS])
    data["damping"] = float(sine_scene.state.walls.control[1, C_DAMPING])
    data["result"] = result
    return data


def _stage(data, k):
    return data["stage"] == k


def test_stress_wall_reaches_and_holds_its_target(run):
    load = _stage(run, 1)
    t = run["time"][load]
    late = t >= t[0] + 0.5 * LOAD
    top = run["wall_normal_stress"][load][late, 1]
    assert late.sum() >= 10
    assert np.max(np.abs(top / SIGMA - 1.0)) < 0.01, top
    bottom = run["wall_normal_stress"][load][late, 0]
    expected = SIGMA + run["weight"] / run["area"]
    assert np.max(np.abs(bottom - expected)) < 0.01 * SIGMA, (bottom, expected)
    # the wall has come to rest: its velocity times the damping is a tiny fraction of the load
    assert np.max(np.abs(run["wall_velocity"][load][late, 1, 2])) < 1e-4


def test_sinusoidal_stress_follows_its_forcing(run):
    sine = _stage(run, 2)
    t = run["time"][sine]
    t = t - t[0]  # a frame is written at the step each stage begins
    keep = t >= 1.0 / FREQUENCY  # the second period: the start transient has passed
    t = t[keep]
    stress = run["wall_normal_stress"][sine][keep, 1]
    z = run["wall_position"][sine][keep, 1]
    w = 2.0 * math.pi * FREQUENCY
    basis = np.stack([np.ones_like(t), np.sin(w * t), np.cos(w * t)], axis=1)
    (mean, s, c), *_ = np.linalg.lstsq(basis, stress, rcond=None)
    gain = math.hypot(s, c) / AMPLITUDE
    phase = math.atan2(c, s)
    (_, zs, zc), *_ = np.linalg.lstsq(basis, z, rcond=None)
    stiffness = AMPLITUDE * run["area"] * gain / math.hypot(zs, zc)  # [N/m]
    # the wall moves down (z decreases) as the stress rises: in phase with -z
    assert math.atan2(-zc, -zs) == pytest.approx(phase, abs=0.1)
    damping = run["damping"]
    lag = math.atan2(damping * w, stiffness - run["mass"] * w * w)
    assert mean == pytest.approx(SIGMA, rel=0.01)
    assert gain == pytest.approx(
        abs(stiffness / complex(stiffness - run["mass"] * w * w, damping * w)), abs=0.02
    )
    assert PHASE - phase == pytest.approx(lag, abs=0.02)
