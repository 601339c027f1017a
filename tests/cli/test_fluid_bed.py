"""A porous bed held in place, given by its porosity in the case file (`[fluid.bed]`, a
Navier-Stokes case without particles; physics/fluid/fixed_bed.py), run through the case file and
the real loop at dt = "auto": Ergun's law through it, stability far beyond its drag relaxation
time, the porosity from a number, an expression or a file, and the errors of bad input.
"""

from __future__ import annotations

import math

import h5py
import numpy as np
import pytest
from cli_test_support import assert_clean_error, edit, sphere_inproc

from sphere_cli.api import run_in_memory
from sphere_cli.simulation import advance

RHO, MU, D = 1000.0, 1e-3, 0.6e-3  # water, grains of 0.6 mm

# Water driven up a laterally periodic column (2 x 2 x 40 cells of 1 mm) by 50 Pa, gravity off,
# through a bed of porosity 0.4 between z = 10 and 30 mm; dt = "auto": 0.9 x the viscous limit
# dx^2/(8 nu) = 0.1125 s.
CASE = """\
title = "a fixed bed of imposed porosity"

[simulation]
duration = 5.7

[domain]
upper = [0.002, 0.002, 0.04]
periodic = [true, true, false]
gravity = [0.0, 0.0, 0.0]

[fluid]
model = "navier-stokes"
formulation = "{formulation}"
grid = {{ cells = [2, 2, 40] }}
bottom = {{ type = "pressure", pressure = 50.0 }}
top = {{ type = "pressure", pressure = 0.0 }}

[fluid.bed]
porosity = 0.4
diameter = 6e-4
lower = 0.01
upper = 0.03
"""


def _ergun(eps: float, superficial: float) -> float:
    """Ergun's pressure gradient [Pa/m] at porosity eps and superficial velocity U [m/s]."""
    linear = 150.0 * MU * (1 - eps) ** 2 * superficial / (eps**3 * D**2)
    return linear + 1.75 * RHO * (1 - eps) * superficial**2 / (eps**3 * D)


@pytest.mark.parametrize("formulation", ["A", "B"])
def test_a_bed_at_the_automatic_dt_is_stable_and_gives_ergun(tmp_path, formulation):
    """The bed's drag relaxation time rho phi/beta (beta = the fluid's drag coefficient in the
    bed, 1.05 ms) is over 100 times below the automatic dt (0.1125 s, the viscous limit); the
    fluid takes the drag implicitly, so the column is stable, and after 50 steps it carries a
    steady flow whose pressure gradient across the bed's middle is Ergun's at that flow and the
    imposed porosity within 1 % (the issue's acceptance; measured: 3e-11 (A), -0.08 % (B)),
    and it passes the run's own stability check (Courant number of the interstitial flow in
    the bed 0.3)."""
    scene = run_in_memory(CASE.format(formulation=formulation), 0, base_dir=tmp_path)
    dt = scene.state.clock.dt
    assert dt == pytest.approx(0.9 * 1e-3**2 / (8 * MU / RHO), rel=1e-9)
    advance(scene, 50)
    fs = scene.state.fluid
    assert np.isfinite(fs.v_face).all() and np.isfinite(fs.p).all()
    assert scene.fluid.first_unstable(scene.state) is None
    assert np.all(fs.porosity[:, :, 10:30] == 0.4) and np.all(fs.porosity[:, :, :10] == 1.0)
    relaxation = RHO * 0.4 / fs.k_drag[:, :, 20].max()
    assert dt > 100 * relaxation
    superficial = float(0.4 * fs.v_face[:, :, 20, 2].mean())
    gradient = float(fs.p[:, :, 13].mean() - fs.p[:, :, 27].mean()) / 14e-3
    assert superficial > 0
    assert gradient == pytest.approx(_ergun(0.4, superficial), rel=0.01)


def test_the_porosity_from_an_expression_or_a_file(tmp_path):
    """An expression is evaluated at the cell centres inside lower..upper (1 elsewhere); a file's
    dataset is taken as it is; both are written to the trajectory as `porosity`."""
    text = edit(CASE.format(formulation="A"), "porosity = 0.4", 'porosity = "0.5 + 0.1*sin(2*pi*z/0.04)"')
    scene = run_in_memory(text, 0, base_dir=tmp_path)
    z = (np.arange(40) + 0.5) * 1e-3
    expected = np.where((z >= 0.01) & (z <= 0.03), 0.5 + 0.1 * np.sin(2 * math.pi * z / 0.04), 1.0)
    assert np.array_equal(scene.state.fluid.porosity[1, 0], expected)

    field = np.random.default_rng(3).uniform(0.3, 1.0, (2, 2, 40))
    with h5py.File(tmp_path / "bed.h5", "w") as f:
        f["porosity"] = field
    text = edit(CASE.format(formulation="A"), "porosity = 0.4\n", 'file = "bed.h5"\n')
    text = edit(text, "lower = 0.01\nupper = 0.03\n", "")
    text = edit(text, "pressure = 50.0", "pressure = 0.0")  # at rest: any porosity field holds
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("run", tmp_path / "case.toml", "--until", "0.2", "--output", tmp_path / "run")
    assert result.code == 0, result.stderr
    with h5py.File(tmp_path / "run" / "trajectory.h5", "r") as f:
        written = f["fluid/porosity/value"][-1]  # (nz, ny, nx): z slowest
    assert np.array_equal(written, field.transpose(2, 1, 0))


BAD = [
    ("above-one", "porosity = 0.4", "porosity = 1.5", ["fluid.bed.porosity", "1.5", "fluid cell (0, 0, 10)"]),
    (
        "below-floor",
        "porosity = 0.4",
        'porosity = "0.4 - 20*z"',
        ["fluid.bed.porosity", "porosity_floor = 0.1", "fluid cell"],
    ),
    ("both", "porosity = 0.4", 'porosity = 0.4\nfile = "bed.h5"', ["fluid.bed", "either"]),
    ("upside-down", "lower = 0.01", "lower = 0.035", ["fluid.bed", "lower = 0.035", "below upper = 0.03"]),
    ("no-diameter", "diameter = 6e-4\n", "", ["fluid.bed.diameter"]),
    ("outside", "upper = 0.03", "upper = 0.0101", ["fluid.bed", "no cell centre"]),
]


@pytest.mark.parametrize(("old", "new", "fragments"), [b[1:] for b in BAD], ids=[b[0] for b in BAD])
def test_bad_bed_input_is_refused_naming_the_key(tmp_path, old, new, fragments):
    (tmp_path / "case.toml").write_text(edit(CASE.format(formulation="A"), old, new))
    result = sphere_inproc("run", tmp_path / "case.toml", "--output", tmp_path / "run")
    assert_clean_error(result, 65, *fragments)
    assert not (tmp_path / "run" / "trajectory.h5").exists()


def test_a_bed_with_particles_is_refused(tmp_path):
    """With particles the porosity comes from them: a [fluid.bed] is refused, naming the key."""
    text = CASE.format(formulation="A").replace(
        "[fluid]\n",
        "[particles]\ncount = 4\nradius = 1e-4\ndensity = 2500.0\n\n"
        '[contact]\nmodel = "linear"\nnormal_stiffness = 1e3\n\n[fluid]\n',
    )
    (tmp_path / "case.toml").write_text(text)
    for args in (("validate",), ("run", "--output", tmp_path / "run")):
        result = sphere_inproc(args[0], tmp_path / "case.toml", *args[1:])
        assert_clean_error(result, 65, "fluid.bed", "without particles")
