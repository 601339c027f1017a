"""Per-particle material and motion from a placement file: a `material` column naming entries of
particles.material, a `group` column naming particles.groups entries and a `fixed` column, in
CSV and HDF5 files; each mistake in them refused by name."""

from __future__ import annotations

import h5py
import numpy as np
import pytest
from cli_test_support import FROM_FILE, assert_clean_error, edit, line_of, sphere_inproc

from sphere_cli.api import run_in_memory

TWO_MATERIALS = edit(FROM_FILE, "density = 2500.0", 'material = ["glass", "steel"]') + (
    '[[materials]]\nname = "glass"\ndensity = 2500.0\n[[materials]]\nname = "steel"\ndensity = 7800.0\n'
)
THREE = (
    "x,y,z,r,material\n0.002,0.005,0.005,0.001,steel\n0.005,0.005,0.005,0.001,glass\n"
    "0.008,0.005,0.005,0.001,steel\n"
)
GROUPS = FROM_FILE + (
    '[[particles.groups]]\nname = "anvil"\nmotion = "fixed"\n'
    '[[particles.groups]]\nname = "piston"\nmotion = "velocity"\nvelocity = [0.0, 0.0, -0.1]\n'
)
SPHERE_MASS = 4.0 / 3.0 * np.pi * 1e-9  # radius 1 mm, per unit density


def _write(tmp_path, case: str, csv: str | None = None):
    (tmp_path / "case.toml").write_text(case)
    if csv is not None:
        (tmp_path / "spheres.csv").write_text(csv)


def test_material_column_says_which_particle_is_made_of_which(tmp_path):
    _write(tmp_path, TWO_MATERIALS, THREE)
    p = run_in_memory(TWO_MATERIALS, 0, tmp_path).state.particles
    assert p.material.tolist() == [1, 0, 1]  # material id k is the k-th name of particles.material
    assert np.allclose(p.mass, np.array([7800.0, 2500.0, 7800.0]) * SPHERE_MASS, rtol=1e-12)
    # the column wins over number fractions, which would deal them at random
    table = edit(TWO_MATERIALS, 'material = ["glass", "steel"]', "material = { glass = 0.5, steel = 0.5 }")
    assert run_in_memory(table, 0, tmp_path).state.particles.material.tolist() == [1, 0, 1]


def test_group_and_fixed_columns_prescribe_the_motion(tmp_path):
    csv = (
        "x,y,z,r,group,fixed\n0.002,0.005,0.002,0.001,anvil,0\n0.005,0.005,0.005,0.001,,0\n"
        "0.008,0.005,0.008,0.001,piston,false\n0.005,0.002,0.008,0.0008,,1\n"
    )
    _write(tmp_path, GROUPS, csv)
    scene = run_in_memory(GROUPS, 50, tmp_path)
    p = scene.state.particles
    assert (
        p.inv_mass.tolist()[0] == 0.0 and p.inv_mass[1] > 0 and p.inv_mass[2] == 0.0 and p.inv_mass[3] == 0.0
    )
    assert np.array_equal(p.vel[2], [0.0, 0.0, -0.1])  # the piston moves at its velocity
    t = scene.state.clock.time
    assert np.allclose(p.pos[2], [0.008, 0.005, 0.008 - 0.1 * t], rtol=0, atol=1e-15)
    assert np.array_equal(p.pos[0], [0.002, 0.005, 0.002]) and np.array_equal(p.pos[3], [0.005, 0.002, 0.008])
    assert p.vel[1, 2] < 0.0  # the free one falls


def test_hdf5_file_gives_material_group_and_fixed(tmp_path):
    with h5py.File(tmp_path / "spheres.h5", "w") as f:
        f["position"] = [[0.002, 0.005, 0.005], [0.005, 0.005, 0.005], [0.008, 0.005, 0.005]]
        f["radius"] = [0.001, 0.001, 0.001]
        f["material"] = np.array(["steel", "glass", "glass"], dtype=h5py.string_dtype())
        f["group"] = np.array(["", "anvil", ""], dtype=h5py.string_dtype())
        f["fixed"] = np.array([0, 0, 1], dtype=np.uint8)
    text = edit(TWO_MATERIALS, "spheres.csv", "spheres.h5") + GROUPS[len(FROM_FILE) :]
    p = run_in_memory(text, 0, tmp_path).state.particles
    assert p.material.tolist() == [1, 0, 0]
    assert p.inv_mass[0] > 0.0 and p.inv_mass[1] == 0.0 and p.inv_mass[2] == 0.0


@pytest.mark.parametrize("command", ["run", "validate"])
def test_an_unknown_hdf5_dataset_is_refused_by_name(tmp_path, command):
    """As a CSV's unknown column: radii under another name would leave every particle the
    particles.radius of the case (1 mm here, against the file's 0.5 mm), a plausible wrong scene.
    Groups and attributes are not read and may hold anything."""
    with h5py.File(tmp_path / "spheres.h5", "w") as f:
        f["position"] = [[0.002, 0.005, 0.005], [0.008, 0.005, 0.005]]
        f["radii"] = [0.0005, 0.0005]
        f.create_group("provenance").attrs["made_by"] = "a notebook"
    (tmp_path / "case.toml").write_text(edit(FROM_FILE, "spheres.csv", "spheres.h5"))
    args = ("run", "case.toml", "-o", "out", "-q") if command == "run" else ("validate", "case.toml")
    result = sphere_inproc(*args, cwd=tmp_path)
    assert_clean_error(result, 65, "spheres.h5", "unknown dataset 'radii' (the radii are in radius)")
    assert not (tmp_path / "out").exists()
    with h5py.File(tmp_path / "spheres.h5", "a") as f:
        f.move("radii", "radius")
    assert sphere_inproc(*args, cwd=tmp_path).code == 0


@pytest.mark.parametrize(
    ("case", "csv", "fragments"),
    [
        (
            TWO_MATERIALS,
            THREE.replace("glass", "brass"),
            ["particles.placement.path", "particle 1 is made of 'brass'", "names glass, steel"],
        ),
        (
            FROM_FILE,
            THREE,
            ["particles.placement.path", "names materials (glass, steel)", "particles.material"],
        ),
        (TWO_MATERIALS, "x,y,z,r\n0.005,0.005,0.005,0.001\n", ["particles.material", "the file has none"]),
        (
            GROUPS,
            "x,y,z,r,group\n0.005,0.005,0.005,0.001,hammer\n",
            ["particle 0 is in group 'hammer'", "anvil"],
        ),
        (
            FROM_FILE,
            "x,y,z,r,fixed\n0.005,0.005,0.005,0.001,maybe\n",
            ["spheres.csv:2: column fixed (column 5)"],
        ),
        (
            FROM_FILE,
            "x,y,x,r\n0.005,0.005,0.005,0.001\n",
            ["spheres.csv:1: the header names 'x' more than once"],
        ),
    ],
    ids=[
        "unknown-material",
        "column-without-materials",
        "list-without-column",
        "unknown-group",
        "bad-flag",
        "twice",
    ],
)
@pytest.mark.parametrize("command", ["run", "validate"])
def test_mistakes_in_the_columns_are_refused_by_name(tmp_path, case, csv, fragments, command):
    """By `sphere validate` too, which reads the file as the build does (a batch job validated
    before it is queued does not fail at its start)."""
    _write(tmp_path, case, csv)
    args = ("run", "case.toml", "-o", "out", "-q") if command == "run" else ("validate", "case.toml")
    result = sphere_inproc(*args, cwd=tmp_path)
    assert_clean_error(result, 65, *fragments)
    assert not (tmp_path / "out").exists()


def test_validate_refuses_a_material_list_without_a_file_and_a_group_that_selects_nothing(tmp_path):
    text = edit(TWO_MATERIALS, 'placement = { method = "file", path = "spheres.csv" }', "count = 4")
    _write(tmp_path, text)
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert_clean_error(
        result, 65, "particles.material", f"case.toml:{line_of(text, 'material =')}:", "placement file"
    )
    text = FROM_FILE + '[[particles.groups]]\nmotion = "fixed"\n'
    _write(tmp_path, text)
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert_clean_error(result, 65, "particles.groups[0]", "give a region")
