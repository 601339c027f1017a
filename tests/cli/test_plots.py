"""`sphere plot` on every example case: the headline figures of each kind of run (strain.png for
the staged experiments, pore_pressure.png for Darcy, the bedload profiles and series for 1D VANS,
the fluid slices for Navier-Stokes, structure.png wherever the packing is recorded), every axis
labelled with a unit in brackets, and no axis without data.

The experiments run shortened (every duration divided by 20, as in test_experiment_configs.py),
the other cases for a few frames.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

import numba
import pytest

from sphere_cli import api
from sphere_cli.io import plot

CONFIGS = Path(__file__).parents[2] / "configs"
EXPERIMENTS = {"consolidation", "uniaxial-strain", "triaxial", "direct-shear"}
TIME_SERIES = {"stress", "friction", "deformation", "energy", "structure"}
EXPECTED = {
    **{name: TIME_SERIES | {"strain"} for name in EXPERIMENTS},
    "demo": {"energy", "structure"},
    "hertz-mixture": {"energy", "structure"},
    "periodic-bed": {"energy", "structure"},
    "seepage-pulses-darcy": {"energy", "pore_pressure"},
    "bedload": {"energy", "bedload_profiles", "bedload_series"},
    "bedload-deposition": {"energy", "bedload_profiles", "bedload_series"},
    "bedload-yade": {"energy", "bedload_profiles", "bedload_series"},
    "fluid-settling": {"energy", "fluid_slices"},
    "fluidized-bed": {"energy", "fluid_slices"},
}
UNIT = re.compile(r"\[[^\]]+\]")  # "[Pa]", "[-]", "[m s-1]"


def test_every_example_case_has_its_plot_set():
    assert {p.stem for p in CONFIGS.glob("*.toml")} == set(EXPECTED)


def _until(name: str) -> float | None:
    """None (run shortened in full) for an experiment; else a few frames' worth of time [s]."""
    if name in EXPERIMENTS:
        return None
    case = tomllib.loads((CONFIGS / f"{name}.toml").read_text())
    every = case["output"]["frames"]["every_time"]
    fluid = case.get("fluid", {}).get("model")
    return 0.002 if fluid == "navier-stokes" else min(2.5 * every, case["simulation"]["duration"])


@pytest.fixture(autouse=True)
def one_thread():
    previous = numba.get_num_threads()
    numba.set_num_threads(1)  # small scenes
    yield
    numba.set_num_threads(previous)


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_plot_draws_the_headline_figures_with_units(tmp_path, monkeypatch, name):
    case = tmp_path / f"{name}.toml"
    text = (CONFIGS / f"{name}.toml").read_text()
    if name in EXPERIMENTS:
        text = re.sub(
            r"\b((?:duration|min_time) = )([0-9.eE+-]+)", lambda m: f"{m[1]}{float(m[2]) / 20!r}", text
        )
    case.write_text(text)
    for bed in CONFIGS.glob("*.csv"):  # the beds of the bedload cases, beside the case
        (tmp_path / bed.name).write_text(bed.read_text())
    api.run(case, tmp_path / "run", until=_until(name))

    figures = {}
    real_save = plot._save

    def keep(fig, path, plt):
        figures[path.stem] = [
            (ax.get_xlabel(), ax.get_ylabel(), len(ax.lines) + len(ax.images) + len(ax.collections))
            for ax in fig.axes
            if ax.get_label() != "<colorbar>"
        ]
        return real_save(fig, path, plt)

    monkeypatch.setattr(plot, "_save", keep)
    written = api.plot(tmp_path / "run")
    assert {p.stem for p in written} == set(figures) == EXPECTED[name]
    assert all(p.is_file() and p.stat().st_size > 10_000 for p in written)
    for figure, axes in figures.items():
        for xlabel, ylabel, drawn in axes:
            assert drawn, f"{figure}.png has an empty axis ({xlabel!r}, {ylabel!r})"
            assert UNIT.search(ylabel), f"{figure}.png: y label {ylabel!r} has no unit"
        assert any(UNIT.search(x) for x, _, _ in axes), f"{figure}.png: no x label with a unit"
