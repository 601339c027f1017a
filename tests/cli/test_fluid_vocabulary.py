"""One name per concept across the fluid models (user guide, "What every fluid model shares"):
a case written with a key of earlier versions is refused (exit 65) with a message that names the
key, its line and the key that replaces it; the example cases use the new names."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest
from cli_test_support import assert_clean_error, edit, line_of, sphere_inproc

CONFIGS = Path(__file__).parents[2] / "configs"

# (case of configs/, its text, the old text, the old key, the new key named)
OLD_KEYS = [
    ("fluid-settling", "steps = 10 ", "ndem = 10 ", "fluid.coupling.ndem", "fluid.coupling.steps"),
    (
        "fluid-settling", "steps = 10 ", "fluid_dt = 1e-3 ", "fluid.coupling.fluid_dt",
        "fluid.coupling.interval",
    ),
    (
        "fluid-settling", 'model = "navier-stokes"', 'model = "navier-stokes"\nbeta = 0.5', "fluid.beta",
        "fluid.old_pressure_weight",
    ),
    (
        "fluid-settling",
        'top = { type = "pressure", pressure = 0.0 }',
        'top = { type = "pressure", pressure = 0.0, amplitude = 1.0, frequency = 10.0 }',
        "fluid.top.frequency",
        "fluid.top.period (= 1/frequency)",
    ),
    (
        "seepage-pulses-darcy", 'bottom = { type = "pressure"', 'bottom = { condition = "pressure"',
        "fluid.bottom.condition", "fluid.bottom.type",
    ),
    (
        "seepage-pulses-darcy", 'model = "darcy"', 'model = "darcy"\nupdate_every = 2', "fluid.update_every",
        "fluid.coupling.steps",
    ),
    (
        "bedload", "coupling = { interval = 1.0e-3 }", "coupling_interval = 1.0e-3",
        "fluid.coupling_interval", "fluid.coupling.interval",
    ),
    (
        "bedload", 'model = "vans1d"', 'model = "vans1d"\nphi_max = 0.6', "fluid.phi_max",
        "fluid.packed_solid_fraction",
    ),
]  # fmt: skip


@pytest.mark.parametrize("name, new, old, key, replacement", OLD_KEYS, ids=[k[3] for k in OLD_KEYS])
def test_a_key_of_earlier_versions_names_its_replacement(tmp_path, name, new, old, key, replacement):
    text = edit((CONFIGS / f"{name}.toml").read_text(), new, old)
    (tmp_path / "case.toml").write_text(text)
    shutil.copy(CONFIGS / "bedload-bed.csv", tmp_path)
    result = sphere_inproc("validate", tmp_path / "case.toml")
    line = line_of(text, old.splitlines()[-1].split(" = ")[0].split("{")[-1].strip() + " =")
    assert_clean_error(result, 65, key, f"now {replacement}", f"case.toml:{line}:")


def test_an_interval_and_steps_together_are_refused(tmp_path):
    text = edit((CONFIGS / "fluid-settling.toml").read_text(), "steps = 10 ", "steps = 10\ninterval = 1e-3\n")
    (tmp_path / "case.toml").write_text(text)
    result = sphere_inproc("validate", tmp_path / "case.toml")
    assert_clean_error(result, 65, "fluid.coupling", "give either steps or interval, not both")


def test_darcy_and_vans1d_take_the_coupling_as_steps_or_interval(tmp_path):
    """The same [fluid.coupling] table in every model: Darcy by interval, vans1d by steps."""
    darcy = edit(
        (CONFIGS / "seepage-pulses-darcy.toml").read_text(),
        'model = "darcy"',
        'model = "darcy"\ncoupling = { interval = 1.0e-5 }',
    )
    bedload = edit(
        (CONFIGS / "bedload.toml").read_text(), "coupling = { interval = 1.0e-3 }", "coupling = { steps = 7 }"
    )
    shutil.copy(CONFIGS / "bedload-bed.csv", tmp_path)
    from sphere_cli.config.load import parse_case
    from sphere_cli.scene.builder import build_scene

    for text, expected in ((darcy, None), (bedload, 7)):
        scene = build_scene(parse_case(text, tmp_path / "case.toml"))
        dt = scene.state.clock.dt
        steps = scene.fluid.coupling_steps
        assert steps == (expected or max(1, round(1.0e-5 / dt)))
        assert scene.fluid.fluid_dt == steps * dt
