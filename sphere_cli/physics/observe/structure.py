"""Packing structure observables (on the observables schedule only): the sample
region and its interior, solid fractions (sample, interior, per layer), coordination numbers.
See kernels/observe/structure.py.

Sample region, per axis: the whole box along a periodic axis; otherwise from the wall on each
face that has one, and from the particles' extent (lowest x - r, highest x + r) on a face
without. Interior: the sample shrunk by `interior_margin` largest diameters on every bounded
face (walls and free surfaces), so the layers that walls order and the loose surface are left
out.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...kernels.laws import MU
from ...kernels.observe.structure import (
    contact_counts,
    layer_solid_volume,
    region_solid_volume,
    remove_rattlers,
    touching_pairs,
)
from ...state import State

UNITS = {
    "packing_fraction": "",
    "packing_fraction_interior": "",
    "coordination": "",
    "coordination_no_rattlers": "",
    "rattler_fraction": "",
}


@dataclass
class Region:
    lower: np.ndarray  # (3,) [m]
    upper: np.ndarray  # (3,) [m]
    bounded: np.ndarray  # (3,) uint8: cut by walls or free surfaces (not a periodic axis)

    @property
    def volume(self) -> float:
        return float(np.prod(np.maximum(self.upper - self.lower, 0.0)))

    def shrunk(self, margin: float) -> Region:
        lower = self.lower + margin * self.bounded
        upper = self.upper - margin * self.bounded
        return Region(lower, upper, self.bounded)

    def holds(self, pos: np.ndarray) -> np.ndarray:
        return np.all((pos >= self.lower) & (pos < self.upper), axis=1)


def wall_arrays(state: State):
    """(axis, sign, coord) of the walls, empty arrays without walls."""
    w = state.walls
    if w is None:
        return np.zeros(0, dtype=np.int64), np.zeros(0), np.zeros(0)
    return w.axis, w.sign, w.coord


def sample_region(state: State) -> Region:
    p, box = state.particles, state.box
    lower = box.lower.astype(np.float64).copy()
    upper = box.upper.astype(np.float64).copy()
    bounded = np.zeros(3, dtype=np.uint8)
    axis, sign, coord = wall_arrays(state)
    for a in range(3):
        if box.periodic[a]:
            continue
        bounded[a] = 1
        lower[a] = float(np.min(p.pos[:, a] - p.radius))
        upper[a] = float(np.max(p.pos[:, a] + p.radius))
        for w in np.flatnonzero(axis == a):
            if sign[w] > 0:
                lower[a] = float(coord[w])
            else:
                upper[a] = float(coord[w])
    return Region(lower, upper, bounded)


def packing_fractions(state: State, sample: Region, interior: Region) -> dict[str, float]:
    p = state.particles
    values = {}
    for name, region in (("packing_fraction", sample), ("packing_fraction_interior", interior)):
        volume = region.volume
        solid = region_solid_volume(p.pos, p.radius, region.lower, region.upper, region.bounded)
        values[name] = float(solid / volume) if volume > 0.0 else float("nan")
    return values


def layer_fractions(state: State, sample: Region, layers: int) -> np.ndarray:
    """Solid fraction of each of `layers` horizontal layers of the sample [-]."""
    dz = (sample.upper[2] - sample.lower[2]) / layers
    area = float(np.prod(sample.upper[:2] - sample.lower[:2]))
    solid = np.zeros(layers)
    layer_solid_volume(state.particles.pos, state.particles.radius, float(sample.lower[2]), dz, solid)
    return solid / (area * dz)


def coordination(state: State, table: np.ndarray, interior: Region) -> dict[str, float]:
    """Mean number of contacts (particles and walls) of the particles whose centre lies in the
    interior: of all of them, and of those left after removing rattlers (fewer than 4 contacts
    when every friction coefficient is 0, fewer than 2 otherwise), and the rattlers' share."""
    p, box, nl = state.particles, state.box, state.neighbors
    axis, sign, coord = wall_arrays(state)
    pairs = np.zeros((int(np.minimum(nl.nbr_count, nl.nbr.shape[1]).sum()), 2), dtype=np.int64)
    found = touching_pairs(p.pos, p.radius, nl.nbr, nl.nbr_count, box.length, box.periodic, pairs)
    pairs = pairs[:found]
    count = np.zeros(p.count, dtype=np.int64)
    contact_counts(p.pos, p.radius, p.inv_mass, pairs, axis, sign, coord, count)
    inside = interior.holds(p.pos)
    if not inside.any():
        nan = float("nan")
        return {"coordination": nan, "coordination_no_rattlers": nan, "rattler_fraction": nan}
    all_mean = float(count[inside].mean())
    frictionless = not np.any(table[..., MU] > 0.0)  # the pair table in force now
    alive = np.ones(p.count, dtype=np.bool_)
    remove_rattlers(pairs, 4 if frictionless else 2, count, alive)
    kept = inside & alive
    return {
        "coordination": all_mean,
        "coordination_no_rattlers": float(count[kept].mean()) if kept.any() else float("nan"),
        "rattler_fraction": float(1.0 - kept.sum() / inside.sum()),
    }
