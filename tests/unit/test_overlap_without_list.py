"""scene/packing.py worst_overlap_of, the overlap check `sphere validate` makes without the
neighbour list (no kernel compiled), against every pair compared directly, in boxes walled and
periodic, with radii spread over a factor of 4 and cells many, two or one along an axis (a
periodic axis of one or two cells wraps a neighbour cell onto one seen already)."""

from __future__ import annotations

import numpy as np
import pytest

from sphere_cli.scene.packing import worst_overlap_of


def every_pair(pos, radius, length, periodic):
    """(i, j, overlap / smaller radius) of the worst pair over all n(n-1)/2 pairs."""
    d = pos[None, :, :] - pos[:, None, :]
    d -= np.where(periodic.astype(bool), length * np.round(d / length), 0.0)
    dist = np.sqrt((d * d).sum(axis=2))
    rel = (radius[:, None] + radius[None, :] - dist) / np.minimum(radius[:, None], radius[None, :])
    rel[np.tril_indices(radius.size)] = -np.inf
    i, j = np.unravel_index(int(np.argmax(rel)), rel.shape)
    return (int(i), int(j), float(rel[i, j])) if rel[i, j] > 0.0 else (-1, -1, 0.0)


@pytest.mark.parametrize("periodic", [(0, 0, 0), (1, 1, 0), (1, 1, 1)])
@pytest.mark.parametrize(
    ("count", "upper"),  # 2 mm cells: 10 a side; 2, 15 and 2; 1, 1 and 15
    [(400, (0.02, 0.02, 0.02)), (60, (0.004, 0.03, 0.005)), (30, (0.003, 0.003, 0.03))],
)
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_the_worst_overlap_is_that_of_every_pair(periodic, count, upper, seed):
    rng = np.random.default_rng(seed)
    lower, upper, periodic = np.zeros(3), np.array(upper), np.array(periodic, dtype=np.uint8)
    pos = lower + rng.random((count, 3)) * (upper - lower)
    radius = rng.uniform(0.25e-3, 1.0e-3, count)
    found = worst_overlap_of(pos, radius, lower, upper, periodic)
    expected = every_pair(pos, radius, upper - lower, periodic)
    assert found[:2] == expected[:2] and found[2] == pytest.approx(expected[2], rel=1e-12)


def test_spheres_apart_have_no_overlap_and_one_sphere_has_none():
    pos = np.array([[0.001, 0.001, 0.001], [0.0031, 0.001, 0.001]])
    radius = np.array([1e-3, 1e-3])
    box = (np.zeros(3), np.full(3, 0.01), np.zeros(3, dtype=np.uint8))
    assert worst_overlap_of(pos, radius, *box) == (-1, -1, 0.0)
    assert worst_overlap_of(pos[:1], radius[:1], *box) == (-1, -1, 0.0)
    # across the periodic x boundary: 0.2 mm apart through it, 1.8 mm of overlap
    pos = np.array([[0.0001, 0.005, 0.005], [0.0099, 0.005, 0.005]])
    i, j, overlap = worst_overlap_of(pos, radius, box[0], box[1], np.array([1, 0, 0], dtype=np.uint8))
    assert (i, j) == (0, 1) and overlap == pytest.approx(1.8, rel=1e-9)
