"""The cells of the neighbour search follow the particle count, not the box volume: a sparse
scene lists only its occupied cells (physics/neighbors.py), and the lists it builds are the
lists every cell would give."""

from __future__ import annotations

import textwrap
import tracemalloc

import numpy as np
from test_neighbor_capacity import CASE as PERIODIC_BIMODAL

from sphere_cli.config.load import parse_case
from sphere_cli.physics import neighbors as neighbors_module
from sphere_cli.scene.builder import build_scene
from sphere_cli.simulation import advance

WALLED = textwrap.dedent(
    """
    [simulation]
    duration = 1.0
    [domain]
    upper = [0.012, 0.01, 0.02]
    periodic = [true, false, false]
    [particles]
    count = 400
    density = 2500.0
    seed = 5
    radius = { distribution = "uniform", min = 0.0004, max = 0.0007 }
    placement = { method = "random" }
    velocity = [0.2, 0.1, 0.0]
    [contact]
    model = "linear"
    normal_stiffness = 1.0e3
    friction = 0.5
    [[walls]]
    face = "z-"
    [[walls]]
    face = "y-"
    [[walls]]
    face = "y+"
    """
)


def _sparse(monkeypatch):
    """Every scene built after this takes the occupied-cells way."""
    monkeypatch.setattr(neighbors_module, "CELLS_PER_PARTICLE", 0)
    monkeypatch.setattr(neighbors_module, "DENSE_FLOOR", 0)


def _assert_same_run(case: str, monkeypatch) -> None:
    every = build_scene(parse_case(case))
    _sparse(monkeypatch)
    occupied = build_scene(parse_case(case))
    assert every.neighbors.dense and not occupied.neighbors.dense
    advance(every, 3000)
    advance(occupied, 3000)
    a, b = every.state.neighbors, occupied.state.neighbors
    assert a.builds == b.builds > 1  # the lists were rebuilt as the particles moved
    assert np.array_equal(a.nbr_count, b.nbr_count) and np.array_equal(a.nbr, b.nbr)
    assert np.array_equal(every.state.particles.pos, occupied.state.particles.pos)
    assert np.array_equal(every.state.particles.angvel, occupied.state.particles.angvel)


def test_occupied_cells_give_the_lists_of_every_cell_periodic(monkeypatch):
    _assert_same_run(PERIODIC_BIMODAL, monkeypatch)  # periodic on every axis (z runs wrap)


def test_occupied_cells_give_the_lists_of_every_cell_with_walls(monkeypatch):
    _assert_same_run(WALLED, monkeypatch)


def _one_sphere(radius: float, upper: str) -> str:
    return textwrap.dedent(
        f"""
        [simulation]
        duration = 1.0
        dt = 5.0e-7
        [domain]
        upper = {upper}
        [particles]
        count = 1
        density = 2500.0
        radius = {radius}
        placement = {{ method = "random" }}
        [contact]
        model = "linear"
        normal_stiffness = 1.0e4
        [[walls]]
        face = "z-"
        """
    )


def test_one_small_sphere_in_a_large_box_takes_little_memory():
    """0.1 mm in a 1 x 1 x 0.06 m box: 2.4e9 cells of the search, which took 44 GiB as a
    table of every cell; listing the occupied ones takes bytes. The whole build and a
    thousand steps stay under 20 MB of new arrays. The same scene is built and stepped once
    before: what a process does once (its kernels loaded from Numba's cache or compiled, modules
    imported: 20-25 MB of Python objects when this test ran first in its process) is not the
    scene's memory."""
    advance(build_scene(parse_case(_one_sphere(1e-4, "[1.0, 1.0, 0.06]"))), 2)
    tracemalloc.start()
    try:
        scene = build_scene(parse_case(_one_sphere(1e-4, "[1.0, 1.0, 0.06]")))
        advance(scene, 1000)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    search = scene.neighbors
    assert search.ncell.prod() > 1e9 and not search.dense
    assert search.cell_start.nbytes + search.cell_key.nbytes <= 64
    assert peak < 20e6
    assert scene.state.clock.step == 1000


def test_a_dense_bed_keeps_a_table_of_every_cell():
    scene = build_scene(parse_case(WALLED))
    search = scene.neighbors
    assert search.dense and search.cell_start.size == search.ncell.prod() + 1
