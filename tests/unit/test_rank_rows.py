"""The half rows a rank sends at a list build, by global index, and the list another rank makes
of them (kernels/neighbors.py rows_by_global_index, local_partners, fill_rows; used by
physics/rank_steps.py), the springs a new list carries from such rows (carry_springs_from_rows),
the particles a rank keeps and those that came merged in global order (merge_rows), the
owners' rows placed into the lead's whole list by global index (fill_rows again), the pairs
of two ghosts left out of a list (drop_ghost_pairs), and the ghosts' forces packed into one
message and out of it (rows_out, rows_in)."""

from __future__ import annotations

import numpy as np

from sphere_cli.kernels.neighbors import (
    carry_springs_from_rows,
    drop_ghost_pairs,
    fill_rows,
    local_partners,
    merge_rows,
    row_starts,
    rows_by_global_index,
    rows_in,
    rows_out,
)


def half_rows(rows: dict, n: int, cap: int) -> tuple:
    """A list of n particles with these rows ({i: partners}), rows cap wide, packed."""
    nbr = np.zeros((n, cap), dtype=np.int32)
    nbr_count = np.zeros(n, dtype=np.int32)
    for i, row in rows.items():
        nbr[i, : len(row)] = row
        nbr_count[i] = len(row)
    start = np.zeros(n + 1, dtype=np.int64)
    row_starts(nbr_count, cap, start)
    return nbr, nbr_count, start


def test_rows_travel_by_global_index_and_come_back_without_the_partners_not_held():
    """Particles with global indices 10, 20, ..., 90; rows of 0 to 3 partners. Sent, then received
    by a rank that holds all but global index 50: each row keeps its partners held, in order,
    with their springs; a row's partners far along (the search's doubling steps) are found."""
    gid = np.arange(10, 100, 10, dtype=np.int64)
    cap = 4
    nbr, nbr_count, start = half_rows({0: [1, 2, 8], 1: [4], 2: [3, 4, 5], 5: [6, 8], 6: [7, 8]}, 9, cap)
    hist = np.arange(3 * start[-1], dtype=np.float64).reshape(-1, 3)

    sent = np.array([0, 2, 5, 6], dtype=np.int64)
    row_start = np.zeros(5, dtype=np.int64)
    np.cumsum(nbr_count[sent], out=row_start[1:])
    partner = np.empty(row_start[-1], dtype=np.int64)
    spring = np.empty((row_start[-1], 3))
    rows_by_global_index(sent, gid, nbr, nbr_count, start, hist, True, row_start, partner, spring)
    assert list(partner) == [20, 30, 90, 40, 50, 60, 70, 90, 80, 90]
    assert np.array_equal(spring, np.concatenate([hist[start[i] : start[i + 1]] for i in sent]))

    # the receiver holds every particle but 50 (local index 4 is global 60); the rows it got are
    # those of its particles 10, 30, 60 and 70, the others' rows empty
    held = np.array([10, 20, 30, 40, 60, 70, 80, 90], dtype=np.int64)
    counts = np.zeros(8, dtype=np.int64)
    counts[[0, 2, 4, 5]] = nbr_count[sent]
    received = np.zeros(9, dtype=np.int64)
    np.cumsum(counts, out=received[1:])
    where = np.empty(received[-1], dtype=np.int64)
    kept = np.empty(8, dtype=np.int32)
    local_partners(held, received, partner, where, kept)
    assert list(where) == [1, 2, 7, 3, -1, 4, 5, 7, 6, 7]
    assert list(kept) == [3, 0, 2, 0, 2, 2, 0, 0]

    new_start = np.zeros(9, dtype=np.int64)
    row_starts(kept, cap, new_start)
    new_nbr = np.zeros((8, cap), dtype=np.int32)
    new_hist = np.zeros((new_start[-1], 3))
    fill_rows(received, where, spring, True, new_start, new_nbr, new_hist, np.arange(new_nbr.shape[0]))
    expected = [[1, 2, 7], [], [3, 4], [], [5, 7], [6, 7], [], []]
    assert [list(new_nbr[i, : kept[i]]) for i in range(8)] == expected
    # the pair (30, 50) is gone with its spring; every other spring is where its pair is
    assert np.array_equal(new_hist, np.delete(spring, 4, axis=0))


def test_a_new_list_carries_each_listed_pairs_spring_from_the_rows_by_global_index():
    """Four particles, global indices 3, 5, 8, 12; their rows by global index lie out of order in
    the pool (particle 2's first, then 0's): each pair of the new list that a row names keeps its
    spring, whatever the row's partners not listed now (5 in row 0, 20 in row 2); a new pair
    (0, 8), and every pair of a row with none, start at zero."""
    gid = np.array([3, 5, 8, 12], dtype=np.int64)
    partner = np.array([12, 20, 5, 12], dtype=np.int64)  # row 2: 12, 20; row 0: 5, 12
    spring = np.arange(12, dtype=np.float64).reshape(4, 3) + 1.0
    row_first = np.array([2, 0, 0, 0], dtype=np.int64)
    row_count = np.array([2, 0, 2, 0], dtype=np.int64)
    nbr, nbr_count, start = half_rows({0: [2, 3], 1: [2], 2: [3]}, 4, 3)
    hist = np.full((start[-1], 3), np.nan)
    carry_springs_from_rows(gid, row_first, row_count, partner, spring, nbr, nbr_count, start, hist)
    assert np.array_equal(hist, [[0, 0, 0], spring[3], [0, 0, 0], spring[0]])


def test_the_kept_particles_and_those_that_came_merge_in_the_order_given_each_row_whole():
    """Rows (n, 2) of a part, three of them kept, and two that came: each row of the result the
    one its source names, kept ones by their place in `keep`."""
    kept = np.arange(12.0).reshape(6, 2)
    came = np.array([[-1.0, -2.0], [-3.0, -4.0]])
    keep = np.array([1, 4, 5])
    source = np.array([3, 0, 4, 2, 1])
    out = np.full((5, 2), np.nan)
    merge_rows(kept, keep, came, source, out)
    assert np.array_equal(out, [came[0], kept[1], came[1], kept[5], kept[4]])


def test_the_owners_rows_land_in_the_leads_list_by_global_index():
    """Rows of particles 3, 0 and 2 of four, in the order two ranks sent them (1 has no row):
    each lands in its particle's row of the lead's list, its springs packed from that row's start,
    the slots past a row's end left as they were."""
    gid = np.array([3, 0, 2], dtype=np.int64)
    row_count = np.array([0, 2, 1], dtype=np.int64)
    partner = np.array([1, 3, 3], dtype=np.int64)
    spring = np.array([[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]])
    nbr_count = np.zeros(4, dtype=np.int32)
    nbr_count[gid] = row_count
    start = np.zeros(5, dtype=np.int64)
    row_starts(nbr_count, 3, start)
    nbr = np.full((4, 3), -7, dtype=np.int32)
    hist = np.full((start[-1] + 2, 3), np.nan)
    row_start = np.concatenate(([0], np.cumsum(row_count)))
    fill_rows(row_start, partner, spring, True, start, nbr, hist, gid)
    assert nbr.tolist() == [[1, 3, -7], [-7, -7, -7], [3, -7, -7], [-7, -7, -7]]
    assert np.array_equal(hist[:3], spring) and np.isnan(hist[3:]).all()


def test_the_pairs_of_two_ghosts_are_left_out_and_the_rest_keep_their_order_and_springs():
    """Six particles, 2 and 4 not owned (ghosts); rows with spare room (capacity 4). The pair
    (2, 4) goes; a ghost's pair with an owned particle stays, as does every pair of an owned
    one; the rows are packed from the first slot, each spring with its pair."""
    owned = np.array([True, True, False, True, False, True])
    rows = {0: [1, 2, 4], 1: [2, 3], 2: [3, 4, 5], 3: [4], 4: [5]}
    nbr, nbr_count, start = half_rows(rows, 6, 4)
    pairs = [(i, j) for i, row in rows.items() for j in row]
    hist = np.array([[i, j, 10 * i + j] for i, j in pairs], dtype=np.float64)

    drop_ghost_pairs(owned, nbr, nbr_count, start, hist, True)
    kept = [(i, j) for i, j in pairs if owned[i] or owned[j]]
    assert (2, 4) not in kept and len(kept) == len(pairs) - 1
    assert [list(nbr[i, : nbr_count[i]]) for i in range(6)] == [[1, 2, 4], [2, 3], [3, 5], [4], [5], []]
    assert list(start) == [0, 3, 5, 7, 8, 9, 9]
    assert np.array_equal(
        hist[: start[-1]], np.array([[i, j, 10 * i + j] for i, j in kept], dtype=np.float64)
    )


def test_a_ghost_message_carries_each_array_in_its_columns_and_back():
    """Force (n, 3) and a (n, 1) array of particles 4, 1 and 3 packed side by side into a box of
    4 columns, then into other arrays at other places: each row where it came from."""
    rng = np.random.default_rng(5)
    force, other = rng.standard_normal((6, 3)), rng.standard_normal((6, 1))
    box = np.full((3, 4), np.nan)
    rows_out(force, np.array([4, 1, 3]), box, 0)
    rows_out(other, np.array([4, 1, 3]), box, 3)
    assert np.array_equal(box, np.concatenate([force[[4, 1, 3]], other[[4, 1, 3]]], axis=1))
    force_there, other_there = np.zeros((5, 3)), np.zeros((5, 1))
    rows_in(box, np.array([0, 2, 4]), force_there, 0)
    rows_in(box, np.array([0, 2, 4]), other_there, 3)
    assert np.array_equal(force_there[[0, 2, 4]], force[[4, 1, 3]])
    assert np.array_equal(other_there[[0, 2, 4]], other[[4, 1, 3]])
    assert not force_there[[1, 3]].any() and not other_there[[1, 3]].any()
