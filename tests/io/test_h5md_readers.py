"""The trajectory opened by the H5MD readers people use, following the recipes of the user guide
(section 5): MDAnalysis and pyh5md. And one unit notation everywhere: every `unit` attribute of
every dataset in a run of every example case parses as an H5MD unit string of SI symbols.

The example runs are a few steps of each case in configs/ (the datasets exist from the first
frame on); the readers read a demo run of some five frames.
"""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import h5py
import MDAnalysis as mda
import numpy as np
import pyh5md
import pytest
from MDAnalysis.coordinates.H5MD import H5MDReader

from sphere_cli import api

CONFIGS = Path(__file__).parents[2] / "configs"
EXAMPLES = sorted(p.stem for p in CONFIGS.glob("*.toml"))

# The H5MD units module (nongnu.org/h5md/modules/units.html): factors separated by one space, at
# most one number and first, then unit symbols each followed by an optional signed non-zero power
NUMBER = re.compile(r"[0-9]+(\.[0-9]+)?")
FACTOR = re.compile(r"(?P<symbol>[A-Za-z]+)(?P<power>-?[1-9][0-9]*)?")
# the SI base and derived units (with their symbols) a granular or fluid quantity can take
SI_SYMBOLS = {"m", "kg", "s", "K", "N", "Pa", "J", "W", "rad"}


def parse_unit(unit: str) -> dict[str, int]:
    """{symbol: power} of an H5MD unit string; raises AssertionError if it is not one."""
    factors = unit.split(" ")
    if NUMBER.fullmatch(factors[0]):
        factors = factors[1:]
    powers: dict[str, int] = {}
    for factor in factors:
        match = FACTOR.fullmatch(factor)
        assert match, f"{unit!r}: {factor!r} is not a unit symbol with an optional power"
        symbol = match["symbol"]
        assert symbol in SI_SYMBOLS, f"{unit!r}: {symbol!r} is not an SI symbol"
        assert symbol not in powers, f"{unit!r}: {symbol!r} appears twice"
        powers[symbol] = int(match["power"] or 1)
    return powers


@pytest.mark.parametrize(
    "unit, expected",
    [("m s-1", {"m": 1, "s": -1}), ("N m-3", {"N": 1, "m": -3}), ("1", {}), ("m2 s-1", {"m": 2, "s": -1})],
)
def test_the_unit_parser_reads_h5md_units(unit, expected):
    assert parse_unit(unit) == expected


@pytest.mark.parametrize("unit", ["m/s", "N/m^3", "m^2", "-", "m  s-1", "m s-0", "m m", "furlong"])
def test_the_unit_parser_refuses_other_notations(unit):
    with pytest.raises(AssertionError):
        parse_unit(unit)


@pytest.fixture(scope="module")
def example_runs(tmp_path_factory) -> dict[str, Path]:
    """A few steps of every example case."""
    root = tmp_path_factory.mktemp("examples")
    for bed in CONFIGS.glob("*.csv"):  # the beds of the bedload cases
        shutil.copy(bed, root)
    runs = {}
    for name in EXAMPLES:
        case = root / f"{name}.toml"
        shutil.copy(CONFIGS / f"{name}.toml", case)
        api.run(case, root / name, until=1e-6)
        runs[name] = root / name
    return runs


def _units(path: Path) -> dict[str, object]:
    """{dataset path: unit attribute} of every item of an HDF5 file that has one."""
    units = {}

    def visit(name, item):
        if "unit" in item.attrs:
            units[name] = item.attrs["unit"]

    with h5py.File(path, "r") as f:
        f.visititems(visit)
    return units


def test_every_unit_of_every_example_run_is_an_h5md_unit(example_runs):
    seen = set()
    for name, run in example_runs.items():
        units = _units(run / "trajectory.h5")
        assert units, name
        for path, unit in units.items():
            assert isinstance(unit, str), f"{name}: {path} unit {unit!r} is not stored as a str"
            parse_unit(unit)
            seen.add(unit)
    # the fluids' velocities, fluxes and force densities, once written in other notations
    assert {"m s-1", "N m-3", "m2 s-1", "1"} <= seen, seen


# --- the readers ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory) -> Path:
    root = tmp_path_factory.mktemp("demo")
    api.run(CONFIGS / "demo.toml", root / "demo", until=0.04)  # frames at 0, 0.01, ... 0.04
    return root / "demo"


def test_mdanalysis_reads_the_trajectory(demo_run):
    # the recipe of the user guide: MDAnalysis knows no metres, so register them and keep SI
    H5MDReader._unit_translation["length"].setdefault("m", "m")
    with h5py.File(demo_run / "trajectory.h5", "r") as f:
        pos = f["particles/trajectory/position"]
        steps, times, values = pos["step"][...], pos["time"][...], pos["value"][...]
        velocities = f["particles/trajectory/velocity/value"][...]
        length = f["particles/trajectory/box/edges/value"][-1]
    universe = mda.Universe.empty(values.shape[1], trajectory=False)
    universe.load_new(str(demo_run / "trajectory.h5"), format="H5MD", convert_units=False)
    traj = universe.trajectory
    assert len(traj) == len(steps) >= 5
    assert traj.units == {"time": "s", "length": "m", "velocity": "m/s", "force": "N"}
    for ts in traj:
        assert ts.data["step"] == steps[ts.frame] and ts.time == pytest.approx(times[ts.frame], rel=1e-12)
        # MDAnalysis holds coordinates in float32
        assert np.allclose(ts.positions, values[ts.frame], rtol=1e-6, atol=0)
        assert np.allclose(ts.velocities, velocities[ts.frame], rtol=1e-6, atol=1e-12)
    assert np.allclose(traj.ts.dimensions, [*length, 90.0, 90.0, 90.0])


def test_pyh5md_reads_the_trajectory(demo_run):
    with h5py.File(demo_run / "trajectory.h5", "r") as f:
        last = f["particles/trajectory/position/value"][-1]
        radius = f["particles/trajectory/radius"][...]
        energy = f["observables/kinetic_energy/value"][...]
    with pyh5md.File(str(demo_run / "trajectory.h5"), "r") as f:
        particles = f.particles_group("trajectory")
        position = pyh5md.element(particles, "position")
        edges = pyh5md.element(particles["box"], "edges")
        assert type(position).__name__ == "TimeElement" and type(edges).__name__ == "TimeElement"
        assert position.value.shape == (len(energy), *last.shape) and np.array_equal(position.value[-1], last)
        assert position.value.attrs["unit"] == "m" and position.time.attrs["unit"] == "s"
        assert np.array_equal(edges.value[-1], [0.03, 0.03, 0.06])
        assert np.array_equal(pyh5md.element(particles, "radius")[...], radius)
        assert np.array_equal(pyh5md.element(f["observables"], "kinetic_energy").value[...], energy)
