"""Neighbour-list capacity: a row that overflows is never silently truncated; the list grows
and the result equals a list that had room from the start (design guide §3)."""

from __future__ import annotations

import textwrap

import numpy as np

from sphere_cli.config.load import parse_case
from sphere_cli.physics import neighbors as neighbors_module
from sphere_cli.scene.builder import build_scene
from sphere_cli.simulation import advance

CASE = textwrap.dedent(
    """
    [simulation]
    duration = 1.0
    [domain]
    upper = [0.01, 0.01, 0.01]
    periodic = [true, true, true]
    gravity = [0.0, 0.0, 0.0]
    [particles]
    count = 300
    density = 2500.0
    seed = 3
    radius = { distribution = "bimodal", small = 0.0003, large = 0.0012, large_fraction = 0.1 }
    placement = { method = "random" }
    velocity = [0.1, 0.05, 0.0]
    [contact]
    model = "linear"
    normal_stiffness = 1.0e3
    """
)


def _scene(capacity: int, monkeypatch):
    monkeypatch.setattr(neighbors_module, "INITIAL_CAPACITY", capacity)
    return build_scene(parse_case(CASE))


def test_overflowing_rows_grow_and_match_a_roomy_list(monkeypatch):
    tight = _scene(2, monkeypatch)
    roomy = _scene(64, monkeypatch)
    nl_t, nl_r = tight.state.neighbors, roomy.state.neighbors
    assert nl_r.nbr.shape[1] == 64 and nl_t.nbr.shape[1] < 64  # each list got its own capacity
    assert nl_r.nbr_count.max() > 2, "the scene must overflow a capacity of 2"
    assert nl_t.nbr.shape[1] >= nl_t.nbr_count.max()  # grew to hold every row
    for i in range(nl_t.nbr_count.size):
        k = nl_t.nbr_count[i]
        assert k == nl_r.nbr_count[i]
        assert np.array_equal(nl_t.nbr[i, :k], nl_r.nbr[i, :k])
    advance(tight, 300)
    advance(roomy, 300)
    assert np.array_equal(tight.state.particles.pos, roomy.state.particles.pos)
    assert np.array_equal(tight.state.particles.angvel, roomy.state.particles.angvel)


def test_rows_far_wider_than_needed_narrow_at_the_next_build(monkeypatch):
    """Rows much wider than the longest (a bed that has settled) are narrowed when the list is
    rebuilt QUIET_BUILDS builds after the last growth, to the longest row + HEADROOM; the
    springs survive and the result is unchanged."""
    wide = _scene(2, monkeypatch)
    roomy = _scene(64, monkeypatch)
    monkeypatch.setattr(neighbors_module, "INITIAL_CAPACITY", 2)
    nl = wide.state.neighbors
    advance(wide, 100)
    advance(roomy, 100)
    wide.neighbors._resize(nl, 40)  # as if the rows had grown in a denser past
    wide.neighbors._reverse(nl)
    # not while the rows have grown lately (a compacting packing would reallocate every build)
    wide.neighbors.rebuild(wide.state)
    assert nl.nbr.shape[1] == 40
    for _ in range(neighbors_module.QUIET_BUILDS):
        wide.neighbors.rebuild(wide.state)
    longest = int(nl.nbr_count.max())
    assert nl.nbr.shape[1] == longest + neighbors_module.HEADROOM
    # the springs are packed row after row whatever the width: all listed pairs, in order
    listed = int(np.minimum(nl.nbr_count, nl.nbr.shape[1]).sum())
    assert nl.start[-1] == listed and nl.hist.shape[0] >= listed
    advance(wide, 200)
    advance(roomy, 200)
    assert np.array_equal(wide.state.particles.pos, roomy.state.particles.pos)
    assert np.array_equal(wide.state.particles.angvel, roomy.state.particles.angvel)


def test_full_rows_become_the_hosts_half_rows_with_their_springs():
    """The GPU's full rows (both members of each pair, ascending) back to half rows (j > i, in
    the same order) and packed springs, as the copy back does (physics/device_steps.py): against
    a slot-by-slot reading of the same rows, rows longer than the host's default width included."""
    from sphere_cli.kernels.neighbors import count_half_rows, fill_half_rows, row_starts
    from sphere_cli.physics.neighbors import listed_slots

    n, width = 500, 40
    rng = np.random.default_rng(4)
    count = rng.integers(0, width + 1, n).astype(np.int32)
    full = np.sort(rng.integers(0, n, (n, width)).astype(np.int32), axis=1)
    springs = rng.random((n, width, 3))
    half = np.empty(n, dtype=np.int32)
    count_half_rows(full, count, half)
    expected_rows = [[int(j) for j in full[i, : count[i]] if j > i] for i in range(n)]
    assert half.tolist() == [len(row) for row in expected_rows] and half.max() > 16
    rows = np.zeros((n, int(half.max())), dtype=np.int32)
    start = np.zeros(n + 1, dtype=np.int64)
    pairs = row_starts(half, rows.shape[1], start)
    packed = np.zeros((pairs, 3))
    fill_half_rows(full, count, springs, True, start, rows, packed)
    expected_springs = [springs[i, k] for i in range(n) for k in range(count[i]) if full[i, k] > i]
    assert all(rows[i, : half[i]].tolist() == expected_rows[i] for i in range(n))
    assert not rows[~listed_slots(rows, half)].any()
    np.testing.assert_array_equal(packed, np.array(expected_springs))
