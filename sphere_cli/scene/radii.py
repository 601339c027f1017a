"""Particle radii drawn from the case's distribution with a seeded generator."""

from __future__ import annotations

import numpy as np

from ..config.schema import BimodalRadius, FixedRadius, LognormalRadius, UniformRadius


def draw_radii(dist, count: int, rng: np.random.Generator) -> np.ndarray:
    if isinstance(dist, FixedRadius):
        return np.full(count, dist.value)
    if isinstance(dist, UniformRadius):
        return rng.uniform(dist.min, dist.max, size=count)
    if isinstance(dist, LognormalRadius):
        radii = np.empty(count)
        filled = 0
        while filled < count:  # redraw the tails outside [min, max]
            batch = dist.median * np.exp(dist.sigma * rng.standard_normal(2 * (count - filled) + 8))
            batch = batch[(batch >= dist.min) & (batch <= dist.max)][: count - filled]
            radii[filled : filled + batch.size] = batch
            filled += batch.size
        return radii
    if isinstance(dist, BimodalRadius):
        large = rng.random(count) < dist.large_fraction
        return np.where(large, dist.large, dist.small)
    raise TypeError(f"unknown radius distribution {dist!r}")
