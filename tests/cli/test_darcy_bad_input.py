"""Bad `[fluid] model = "darcy"` input: a short message naming the key and its line, exit 65,
no traceback (the checks of config/fluid_darcy.py and physics/fluid/darcy.py)."""

from __future__ import annotations

import re

import pytest
from cli_test_support import TINY, assert_clean_error, edit, line_of, sphere_inproc

DARCY = TINY.replace("[output.frames]", '[fluid]\nmodel = "darcy"\n\n[output.frames]')

CASE_ERRORS = [
    # (id, text to replace, replacement, key named, text on the line named, other fragments)
    (
        "typo",
        'model = "darcy"',
        'model = "darcy"\nviscosty = 1e-3',
        "fluid.viscosty",
        "viscosty",
        ["unknown key"],
    ),
    (
        "negative-viscosity",
        'model = "darcy"',
        'model = "darcy"\nviscosity = -1e-3',
        "fluid.viscosity",
        "viscosity",
        ["greater than 0"],
    ),
    (
        "modulation-without-period",
        'model = "darcy"',
        'model = "darcy"\ntop = { amplitude = 50.0 }',
        "fluid.top",
        "top =",
        ["needs its period"],
    ),
    (
        "unknown-boundary-condition",
        'model = "darcy"',
        'model = "darcy"\nbottom = { type = "open" }',
        "fluid.bottom.type",
        "bottom =",
        ["unknown choice", '"no-flow"'],
    ),
    (
        "no-flow-with-a-pressure",
        'model = "darcy"',
        'model = "darcy"\nbottom = { type = "no-flow", pressure = 3.0 }',
        "fluid.bottom.pressure",
        "bottom =",
        ["unknown key"],
    ),
    (
        "clamps-reversed",
        'model = "darcy"',
        'model = "darcy"\nporosity_min = 0.6\nporosity_max = 0.5',
        "fluid",
        "[fluid]",
        ["porosity_min (0.6) must be below porosity_max (0.5)"],
    ),
    (
        "unknown-permeability-law",
        'model = "darcy"',
        'model = "darcy"\npermeability = { model = "ergun" }',
        "fluid.permeability.model",
        "permeability =",
        ["unknown choice", '"kozeny-carman"'],
    ),
]


@pytest.mark.parametrize(
    ("old", "new", "key", "marker", "fragments"),
    [c[1:] for c in CASE_ERRORS],
    ids=[c[0] for c in CASE_ERRORS],
)
def test_darcy_case_error_names_key_and_line(tmp_path, old, new, key, marker, fragments):
    text = edit(DARCY, old, new)
    case = tmp_path / "case.toml"
    case.write_text(text)
    result = sphere_inproc("validate", case)
    assert_clean_error(result, 65, key, f"case.toml:{line_of(text, marker)}:", *fragments)


def test_fixed_pressure_region_without_a_cell(tmp_path):
    region = (
        "[[fluid.fixed_pressure]]\nlower = [0.0, 0.0, 0.0]\nupper = [0.001, 0.001, 0.001]\npressure = 1.0\n"
    )
    text = edit(DARCY, "[output.frames]", region + "\n[output.frames]")
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(
        result,
        65,
        "fluid.fixed_pressure[0]",
        f"case.toml:{line_of(text, '[[fluid.fixed_pressure]]')}:",
        "no cell",
    )
    assert not (tmp_path / "out").exists()


def test_periodic_z_is_refused(tmp_path):
    text = edit(
        edit(DARCY, '[[walls]]\nface = "z-"\n', ""),
        "[particles]",
        "periodic = [false, false, true]\n\n[particles]",
    )
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(result, 65, "domain.periodic", "bounded z axis")


def test_the_explicit_scheme_is_refused_with_fixed_pressure_regions(tmp_path):
    text = edit(
        DARCY,
        'model = "darcy"',
        'model = "darcy"\ntime_scheme = "explicit"\n[[fluid.fixed_pressure]]\nlower = [0.0, 0.0, 0.0]\n'
        "upper = [0.01, 0.01, 0.005]\npressure = 10.0",
    )
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert_clean_error(result, 65, "fluid.time_scheme", "fluid.fixed_pressure", 'time_scheme = "implicit"')


@pytest.mark.parametrize("command", ["validate", "run"])
def test_dt_above_the_explicit_diffusion_limit_names_it(tmp_path, command):
    """time_scheme = "explicit" with Kozeny-Carman (k_c = d^2/180, d = 1.8 mm): D = k/(beta_f phi mu)
    peaks at porosity_max = 0.9, about 3e4 m^2/s, so the limit is nanoseconds on 2.5 mm cells: the
    default contact time step is refused naming it."""
    text = edit(DARCY, 'model = "darcy"', 'model = "darcy"\ntime_scheme = "explicit"')
    text = edit(text, 'dt = "auto"', "dt = 1e-6")
    (tmp_path / "case.toml").write_text(text)
    args = ("validate",) if command == "validate" else ("run", "-o", "out", "-q")
    result = sphere_inproc(args[0], "case.toml", *args[1:], cwd=tmp_path)
    assert_clean_error(result, 65, "simulation.dt", 'time_scheme = "explicit"', "diffusion limit")


@pytest.mark.parametrize("command", ["validate", "run"])
def test_dt_above_the_coupling_limit_names_it(tmp_path, command):
    """k = 1e-14 m^2: the coupling's limit 0.2 rho_s k (1 - porosity_max) / mu = 0.2 x 2500 x
    1e-14 x 0.1 / 1e-3 = 5e-10 s is below the contact limit; a dt of 1e-6 s is refused naming it."""
    law = 'permeability = { model = "constant", value = 1e-14 }'
    text = edit(edit(DARCY, 'model = "darcy"', f'model = "darcy"\n{law}'), 'dt = "auto"', "dt = 1e-6")
    (tmp_path / "case.toml").write_text(text)
    args = ("validate",) if command == "validate" else ("run", "-o", "out", "-q")
    result = sphere_inproc(args[0], "case.toml", *args[1:], cwd=tmp_path)
    assert_clean_error(result, 65, "simulation.dt", "explicit Darcy coupling", "limit 5e-10 s")


def _modulated(tmp_path, period: float):
    """DARCY with its top pressure modulated at `period` [s] (dt = "auto" is 1.124e-6 s, one DEM
    step a fluid step), in case.toml."""
    top = f'top = {{ type = "pressure", amplitude = 10.0, period = {period!r} }}'
    text = edit(DARCY, 'model = "darcy"', f'model = "darcy"\n{top}')
    (tmp_path / "case.toml").write_text(text)
    return text


@pytest.mark.parametrize("command", ["validate", "run"])
def test_a_modulation_faster_than_the_fluid_step_is_refused(tmp_path, command):
    """A period of 1.5 fluid steps, sampled at the steps, would alias into a slower modulation (a
    plausible wrong answer): refused before the run, naming the key, its line and the bounds."""
    text = _modulated(tmp_path, 1.7e-6)
    args = ("validate",) if command == "validate" else ("run", "-o", "out", "-q")
    result = sphere_inproc(args[0], "case.toml", *args[1:], cwd=tmp_path)
    assert_clean_error(
        result, 65, "fluid.top.period", f"case.toml:{line_of(text, 'top =')}:", "alias", "2 steps a period"
    )
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(("period", "warned"), [(1.1e-5, True), (1e-3, False)])
def test_a_modulation_resolved_by_few_fluid_steps_is_warned_once_on_stderr_and_in_run_log(
    tmp_path, period, warned
):
    """About 10 fluid steps a period: the run goes on, warning once on stderr and in run.log (as
    every warning of the case) that its amplitude and phase carry errors of omega dt/2; 890
    steps a period: no warning."""
    _modulated(tmp_path, period)
    result = sphere_inproc("run", "case.toml", "-o", "out", "-q", cwd=tmp_path)
    assert result.code == 0, result.stderr
    assert result.stderr.count("fluid.top.period") == (1 if warned else 0), result.stderr
    log = (tmp_path / "out" / "run.log").read_text()
    assert ("below 20 steps a period" in log) == warned, log
    # its grid's own step on a thread count of its cells' (runtime.grid_threads), named in run.log
    assert re.search(r"threads: \d+ for the particles' kernels, \d+ for the fluid grid's own step", log), log
