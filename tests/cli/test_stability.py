"""Stability through the command line (verification group E; design guide section 1, promise 2):
a dt above the contact limit is refused before anything runs (exit 65, the limit named with its
value), and a run that does blow up stops with exit 70 naming step, time and particle, while the
newest checkpoint before the failure still verifies and resumes."""

from __future__ import annotations

import json
import math
import re
import xml.etree.ElementTree as ET
from pathlib import Path

import h5py
import pytest
from cli_test_support import TINY, assert_clean_error, line_of, sphere, sphere_inproc

from sphere_cli.config.load import load_case, parse_case
from sphere_cli.io.checkpoint import list_checkpoints, read_checkpoint
from sphere_cli.scene.builder import build_scene


def _errors(stderr: str) -> list[str]:
    return [line for line in stderr.splitlines() if not line.startswith("sphere: warning:")]


HERTZ_MIXTURE = """\
[simulation]
duration = 0.001
dt = {dt}

[domain]
upper = [0.01, 0.01, 0.02]

[particles]
count = 40
material = {{ soft = 0.5, hard = 0.5 }}
radius = {{ distribution = "uniform", min = 0.0007, max = 0.0009 }}

[contact]
model = "hertz-mindlin"

[[materials]]
name = "soft"
density = 1000.0
youngs_modulus = 1.0e7
poisson_ratio = 0.3

[[materials]]
name = "hard"
density = 2500.0
youngs_modulus = 1.0e11
poisson_ratio = 0.25

[[walls]]
face = "z-"
"""

LINEAR = (
    HERTZ_MIXTURE.replace(
        """[contact]
model = "hertz-mindlin"
""",
        """[contact]
model = "linear"
""",
    )
    .replace("youngs_modulus = 1.0e7\npoisson_ratio = 0.3", "normal_stiffness = 1.0e2")
    .replace("youngs_modulus = 1.0e11\npoisson_ratio = 0.25", "normal_stiffness = 1.0e6")
)


@pytest.mark.parametrize("law", ["hertz-mindlin", "linear"])
def test_dt_three_times_the_limit_is_refused(tmp_path, law):
    """verification group E: with two materials 1e4 apart in stiffness, dt = 3 x the stability
    limit is refused with exit 65, naming simulation.dt, its line, the limit and its value (the
    value the scene computes for dt = "auto", printed to 4 digits), and what sets it; no run
    directory is created."""
    text = HERTZ_MIXTURE if law == "hertz-mindlin" else LINEAR
    limit = build_scene(parse_case(text.format(dt='"auto"'))).dt_limit
    case = text.format(dt=repr(3.0 * limit))
    (tmp_path / "case.toml").write_text(case)
    result = sphere("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(result, 65, "simulation.dt", f"case.toml:{line_of(case, 'dt =')}:", "stability limit")
    shown = float(re.search(r"stability limit ([0-9.eE+-]+) s", result.stderr).group(1))
    assert shown == pytest.approx(limit, rel=1e-3)
    assert "material 'hard'" in result.stderr  # the stiff material sets it
    assert not (tmp_path / "out").exists()
    # the limit itself is accepted, for a scene declared never to pack densely (it is above the
    # bound for spheres held by many contacts, tests/physics/test_dt_bound.py)
    (tmp_path / "ok.toml").write_text(text.format(dt=repr(limit) + '\nstability = "contact"'))
    assert build_scene(load_case(tmp_path / "ok.toml")).state.clock.dt == limit


# Two spheres squeezed between the x- and x+ walls, each overlapping its neighbours by 4 % of the
# radius (within overlap_tolerance), started with opposite velocities.
R = 1.0e-3
OVERLAP = 0.04 * R
SQUEEZED = """\
[simulation]
duration = 0.01
dt = {dt}
stability = "contact"
blowup_check_every = 100

[domain]
upper = [{length!r}, 0.01, 0.01]
gravity = [0.0, 0.0, 0.0]

[particles]
density = 2500.0
placement = {{ method = "file", path = "spheres.csv" }}

[contact]
model = "linear"
normal_stiffness = 1.0e3
restitution = 1.0

[[walls]]
face = "x-"
[[walls]]
face = "x+"

[output.frames]
every_steps = 5

[output.checkpoints]
every_steps = 5
keep = 3
"""


def test_blow_up_exits_70_and_the_last_checkpoint_resumes(tmp_path: Path):
    """A real blow-up below the limit: two spheres squeezed between two walls form a chain
    wall-sphere-sphere-wall whose fastest mode, omega^2 = 3 k/m, is sqrt(3/2) faster than any
    single pair or wall contact the limit is computed from (omega^2 = 2 k/m for the pair), so
    dt = 0.95 x dt_limit puts omega dt at 2.3 > 2 and velocity Verlet diverges (the stability
    bound for spheres held by several contacts is below it: the case has to say stability =
    "contact" to run at all; dt = "auto" stays below it). Within a few steps a sphere
    moves more than half its radius per step: the check that runs before every checkpoint (here
    every 5 steps) stops the run with exit 70 naming the step, time and particle; status.json
    says failed, the ParaView sidecar lists every frame written. The newest checkpoint predates
    the failure and verifies; `sphere resume` from it fails again at exactly the same step (the
    run is deterministic), and `sphere resume --until` a time before the failure completes
    (exit 0)."""
    d = 2.0 * R - OVERLAP
    length = 2.0 * (R - OVERLAP) + d
    x0 = R - OVERLAP
    (tmp_path / "spheres.csv").write_text(
        f"x,y,z,r,vx,vy,vz\n{x0!r},0.005,0.005,{R!r},0.01,0.0,0.0\n"
        f"{x0 + d!r},0.005,0.005,{R!r},-0.01,0.0,0.0\n"
    )
    probe = tmp_path / "probe.toml"
    probe.write_text(SQUEEZED.format(dt='"auto"', length=length))
    limit = build_scene(load_case(probe)).dt_limit
    dt = 0.95 * limit
    (tmp_path / "case.toml").write_text(SQUEEZED.format(dt=repr(dt), length=length))

    result = sphere("run", "case.toml", "-o", "run", "-q", cwd=tmp_path)
    assert_clean_error(result, 70, "numerical failure at step", "particle", "(t = ", "checkpoint")
    failed_step = int(re.search(r"failure at step (\d+)", result.stderr).group(1))
    assert 0 < failed_step <= 100
    status = json.loads((tmp_path / "run" / "status.json").read_text())
    assert status["state"] == "failed" and status["step"] == failed_step
    # the ParaView sidecar lists every frame written before the failure (it is rewritten at most
    # every few seconds during a run, and brought up to date when the run fails)
    with h5py.File(tmp_path / "run" / "trajectory.h5", "r") as f:
        frames = f["particles/trajectory/position/step"].shape[0]
    grids = ET.parse(tmp_path / "run" / "trajectory.xmf").getroot().findall(".//Grid[@GridType='Uniform']")
    assert frames > 2 and len(grids) == frames

    ckpts = list_checkpoints(tmp_path / "run" / "checkpoints")
    newest = read_checkpoint(ckpts[-1])  # verifies (checksums, completeness)
    assert failed_step - 5 <= newest.step < failed_step

    again = sphere("resume", "run", "-q", cwd=tmp_path)
    assert_clean_error(again, 70, f"numerical failure at step {failed_step} ")
    # the same error, word for word (a warning about shared cores may precede either)
    assert _errors(again.stderr) == _errors(result.stderr)

    # from the oldest checkpoint kept, ten steps before the failure was caught (the check runs
    # every 5 steps, so the state may have gone bad up to 4 steps before): the newer ones removed
    for path in ckpts[1:]:
        path.unlink()
    target = read_checkpoint(ckpts[0]).step + 2
    done = sphere("resume", "run", "--until", repr(target * dt), "-q", cwd=tmp_path)
    assert_clean_error(done, 0)
    assert json.loads((tmp_path / "run" / "status.json").read_text())["step"] == target


# --- contacts too soft for the particles' weight ----------------------------------------------


def _soft(model: str) -> str:
    contact = (
        "normal_stiffness = 1.0e4"
        if model == "linear"
        else 'model = "hertz-mindlin"\nyoungs_modulus = 2.0e3\npoisson_ratio = 0.3'
    )
    return TINY.replace('model = "linear"\nnormal_stiffness = 1.0e4', contact.replace("1.0e4", "0.01"))


@pytest.mark.parametrize("model", ["linear", "hertz-mindlin"])
def test_contacts_too_soft_for_the_weight_are_warned_of_with_the_overlap(tmp_path, model):
    """The heaviest sphere (m) resting on the floor under its weight overlaps it by m g / k_n
    (linear) or (m g / (4/3 E* sqrt(r)))^(2/3) with E* = E / (1 - nu^2) against a rigid wall
    (Hertz, the stiffest support here: a pair of spheres has half its E* and R*): beyond a tenth
    of its radius the case is warned of, naming the stiffness key and its line."""
    text = _soft(model)
    (tmp_path / "case.toml").write_text(text)
    scene = build_scene(load_case(tmp_path / "case.toml"))
    p = scene.state.particles
    i = int(p.mass.argmax())
    m, r, g = float(p.mass[i]), float(p.radius[i]), 9.81
    if model == "linear":
        key, expected = "contact.normal_stiffness", m * g / 0.01
    else:
        e_star = 2.0e3 / (1.0 - 0.3**2)
        key, expected = "contact.youngs_modulus", (m * g / (4.0 / 3.0 * e_star * r**0.5)) ** (2.0 / 3.0)
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert result.code == 0, result.stderr
    line = next(x for x in result.stderr.splitlines() if "under its own weight" in x)
    assert f"case.toml:{line_of(text, key.split('.')[1])}: {key} = " in line, line
    assert "resting on the z- wall" in line, line
    shown = float(re.search(r"overlaps it by ([0-9.e+-]+) m", line).group(1))
    assert shown == pytest.approx(expected, rel=2e-3), line  # printed to 3 digits
    assert expected > 0.1 * r


def _thrown(tmp_path, contact: str, v: float, r: float = 0.001, density: float = 2500.0) -> float:
    """One sphere thrown at the floor at v [m/s], gravity off, with `contact` ([contact]'s lines):
    writes the case; returns its mass [kg]."""
    (tmp_path / "case.toml").write_text(
        "[simulation]\nduration = 0.001\n[domain]\nupper = [0.01, 0.01, 0.01]\ngravity = [0.0, 0.0, 0.0]\n"
        f'[particles]\ndensity = {density}\nplacement = {{ method = "file", path = "one.csv" }}\n'
        f'[contact]\n{contact}\n[[walls]]\nface = "z-"\n'
    )
    (tmp_path / "one.csv").write_text(f"x,y,z,r,vx,vy,vz\n0.005,0.005,0.005,{r},0.0,0.0,{-v}\n")
    return density * 4.0 / 3.0 * math.pi * r**3


@pytest.mark.parametrize("model", ["linear", "hertz-mindlin"])
def test_contacts_too_soft_for_an_initial_speed_are_warned_of_with_the_overlap(tmp_path, model):
    """One sphere thrown at the floor at 3 m/s: the deepest overlap of the impact, the dashpot
    left out, is v sqrt(m/k_n) (linear: 1/2 m v^2 = 1/2 k delta^2) or (15 m v^2 / (16 E*
    sqrt(r)))^(2/5) against a rigid wall (Hertz); beyond a quarter of its radius the case is
    warned of, naming the stiffness key."""
    r, v = 0.001, 3.0
    if model == "linear":
        m = _thrown(tmp_path, "normal_stiffness = 10.0", v, r)
        key, expected = "contact.normal_stiffness", v * math.sqrt(m / 10.0)
    else:
        m = _thrown(tmp_path, 'model = "hertz-mindlin"\nyoungs_modulus = 1.0e5\npoisson_ratio = 0.3', v, r)
        e_star = 1.0e5 / (1.0 - 0.3**2)
        key, expected = "contact.youngs_modulus", (15.0 * m * v * v / (16.0 * e_star * math.sqrt(r))) ** 0.4
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert result.code == 0, result.stderr
    line = next(x for x in result.stderr.splitlines() if "kinetic energy" in x)
    assert f"{key} = " in line and "3 m/s at the start" in line and "striking the z- wall" in line, line
    shown = float(re.search(r"overlap it by up to ([0-9.e+-]+) m", line).group(1))
    assert shown == pytest.approx(expected, rel=2e-3), line
    assert expected > 0.25 * r


def test_an_impact_that_overlaps_a_tenth_of_a_radius_is_not_warned_of(tmp_path):
    """The A4 verification's impact: 1 m/s on k_n = 1e3 N/m, at most 0.1 of the radius (less with
    its dashpot), resolved to 1e-3: below the quarter that is warned of."""
    m = _thrown(tmp_path, "normal_stiffness = 1000.0", 1.0)
    assert 0.09 < math.sqrt(m / 1000.0) / 0.001 < 0.11
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert result.code == 0 and "kinetic energy" not in result.stderr, result.stderr


def test_contacts_stiff_enough_for_the_weight_are_not_warned_of(tmp_path):
    """TINY's spheres overlap the floor by m g / k_n = 1e-8 m under their weight, 1e-5 of a
    radius: nothing to say."""
    (tmp_path / "case.toml").write_text(TINY)
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert result.code == 0 and "under its own weight" not in result.stderr, result.stderr


def test_a_sphere_fallen_through_the_floor_is_said_to_have_passed_through_the_wall(tmp_path):
    """Contacts a thousand times too soft: the spheres sink through the z- wall and the run
    stops (exit 70) saying so, not that they left through an open face."""
    (tmp_path / "case.toml").write_text(_soft("linear").replace("duration = 0.002", "duration = 0.2"))
    result = sphere("run", "case.toml", "-o", "run", "-q", cwd=tmp_path)
    assert_clean_error(result, 70, "passed through the wall on face z-", "too soft", "stiffen it")
    assert "open face" not in result.stderr
