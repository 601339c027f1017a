"""Observables on their own schedule in trajectory.h5, shown by `sphere inspect`, drawn by
`sphere plot` (and its message when matplotlib is missing), and bad observables keys."""

from __future__ import annotations

import sys

import h5py
import numpy as np
import pytest
from cli_test_support import TINY, TINY_END_STEP, assert_clean_error, edit, line_of, sphere_inproc

from sphere_cli import api

GROUPS = ("energy", "contacts", "packing_fraction", "coordination", "stress", "profiles", "deformation")
ALL = "[" + ", ".join(f'"{g}"' for g in (*GROUPS, "energy_budget")) + "]"
OBSERVED = (
    TINY
    + f"""
[output.observables]
every_steps = 200
quantities = {ALL}
layers = 4
"""
)


@pytest.fixture(scope="module")
def observed_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("observed")
    (root / "case.toml").write_text(OBSERVED)
    api.run(root / "case.toml", root / "run")
    return root / "run"


def test_observables_on_their_own_schedule(observed_run):
    with h5py.File(observed_run / "trajectory.h5", "r") as f:
        frames = f["particles/trajectory/position/step"][...]
        obs = f["observables"]
        steps = obs["pressure/step"][...]
        # every 200 steps from 0, plus the end; frames every 50
        assert steps.tolist() == [*range(0, TINY_END_STEP, 200), TINY_END_STEP]
        assert frames.size == TINY_END_STEP // 50 + 2
        assert obs["stress/value"].shape == (steps.size, 3, 3)
        assert obs["stress/value"].attrs["unit"] == "Pa"
        assert obs["stress_profile/value"].shape == (steps.size, 4, 3, 3)
        assert obs["packing_fraction_profile/value"].shape == (steps.size, 4)
        assert obs["velocity_profile/value"].shape == (steps.size, 4, 3)
        assert obs["layer_center/value"].attrs["unit"] == "m"
        for name in ("work_gravity", "dissipated_damping", "dilation", "coordination", "packing_fraction"):
            assert obs[f"{name}/value"].shape == (steps.size,)
        assert obs["dilation/value"][0] == 0.0
        phi = obs["packing_fraction/value"][...]
        assert np.all((phi > 0.0) & (phi < 0.75))


def test_inspect_shows_observables(observed_run):
    result = sphere_inproc("inspect", observed_run)
    assert result.code == 0, result.stderr
    for name in ("effective_friction:", "stress:", "packing_fraction_profile:", "energy_balance_residual:"):
        assert name in result.stdout
    assert "4 layers" in result.stdout


def test_inspect_reads_observables_a_run_is_appending_to(observed_run, tmp_path):
    """A run appends an observable's step, time and value one after the other: inspect, reading
    between two of those, shows the last sample complete in all three (or none yet)."""
    import shutil

    copy = tmp_path / "run"
    shutil.copytree(observed_run, copy)
    with h5py.File(copy / "trajectory.h5", "r+") as f:
        obs = f["observables"]
        last_pressure = float(obs["pressure/value"][-1])
        for name in ("step", "time"):  # the next sample's step and time written, its value not
            obs[f"pressure/{name}"].resize(obs[f"pressure/{name}"].shape[0] + 1, axis=0)
        obs["coordination/value"].resize(0, axis=0)  # a first sample begun, no value yet
    result = sphere_inproc("inspect", copy / "trajectory.h5")
    assert result.code == 0, result.stderr
    shown = result.stdout.split("last_observables:")[1].split("steady")[0]
    assert f"  pressure: {last_pressure!r}\n" in shown
    assert "  coordination:" not in shown and "  coordination_no_rattlers:" in shown


def test_plot_writes_pngs(observed_run, tmp_path):
    pytest.importorskip("matplotlib")
    result = sphere_inproc("plot", observed_run, "-o", tmp_path / "plots")
    assert result.code == 0, result.stderr
    names = sorted(p.name for p in (tmp_path / "plots").iterdir())
    assert names == sorted(
        ["stress.png", "friction.png", "deformation.png", "energy.png", "structure.png", "profiles.png"]
    )
    for name in names:
        assert (tmp_path / "plots" / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_plot_without_matplotlib_says_how_to_install(observed_run, tmp_path, monkeypatch):
    # a None entry in sys.modules makes `import matplotlib` raise ImportError
    monkeypatch.setitem(sys.modules, "matplotlib", None)
    result = sphere_inproc("plot", observed_run, "-o", tmp_path / "plots")
    assert_clean_error(result, 69, "matplotlib", "pip install 'sphere-cli[plot]'")
    assert not (tmp_path / "plots").exists()


def test_plot_of_a_missing_run(tmp_path):
    assert_clean_error(sphere_inproc("plot", tmp_path / "nothing"), 66, "no trajectory")


@pytest.mark.parametrize(
    ("new", "key", "fragment"),
    [
        ('quantities = ["energy", "stres"]', "output.observables.quantities", "stres"),
        (
            'quantities = ["energy", "energy"]',
            "output.observables.quantities",
            "listed more than once: energy",
        ),
        ("layers = 0", "output.observables.layers", "greater than or equal to 1"),
        ("interior_margin = -1.0", "output.observables.interior_margin", "greater than or equal to 0"),
        ('shear_direction = "z"', "output.observables.shear_direction", "z"),
    ],
    ids=["unknown-quantity", "repeated-quantity", "no-layers", "negative-margin", "vertical-shear"],
)
def test_bad_observables_keys(tmp_path, new, key, fragment):
    old = f"quantities = {ALL}" if new.startswith("quantities") else "layers = 4"
    text = edit(OBSERVED, old, new)
    case = tmp_path / "case.toml"
    case.write_text(text)
    marker = new.split(" =")[0]
    result = sphere_inproc("validate", case)
    assert_clean_error(result, 65, key, f"case.toml:{line_of(text, marker + ' =')}:", fragment)


def test_inspect_json_is_strict_json_where_an_observable_has_no_value(tmp_path):
    """An interior margin wider than the sample leaves the interior observables NaN (the run
    warns once): `sphere inspect --json` wrote them as the bare token NaN, which strict JSON
    parsers (JavaScript's JSON.parse, Go's, serde_json) refuse for the whole report; they are
    null now, and status.json too is strict JSON."""
    import json

    (tmp_path / "case.toml").write_text(OBSERVED.replace("layers = 4", "layers = 4\ninterior_margin = 100.0"))
    api.run(tmp_path / "case.toml", tmp_path / "run")
    assert "leaves no interior" in (tmp_path / "run" / "run.log").read_text()
    result = sphere_inproc("inspect", tmp_path / "run", "--json")
    assert result.code == 0, result.stderr

    def refuse(token):
        raise ValueError(f"{token} is not JSON")

    shown = json.loads(result.stdout, parse_constant=refuse)
    last = shown["trajectory"]["last_observables"]
    assert last["coordination"] is None and last["packing_fraction_interior"] is None
    assert last["packing_fraction"] > 0.0
    json.loads((tmp_path / "run" / "status.json").read_text(), parse_constant=refuse)
