"""Horizontal layers of a laterally periodic cell, and the particles averaged over them
(kernels/fluid/layer_averaging.py): solid fraction, mean streamwise velocity, momentum exchange
coefficient and drag per unit volume, one value per layer.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...kernels.fluid.layer_averaging import layer_average


def layer_faces(bottom: float, top: float, cells: int, stretching: float = 1.0) -> np.ndarray:
    """Faces of `cells` layers from bottom to top whose thicknesses grow geometrically so that
    the top one is `stretching` times the bottom one (a smooth mapping: refining keeps the
    shape, which keeps the scheme second order)."""
    if cells < 1 or not top > bottom or stretching < 1.0:
        raise ValueError(
            f"need cells >= 1, top > bottom, stretching >= 1; got {cells}, {bottom}, {top}, {stretching}"
        )
    if stretching == 1.0 or cells == 1:
        widths = np.ones(cells)
    else:
        widths = stretching ** (np.arange(cells) / (cells - 1))
    faces = np.empty(cells + 1)
    faces[0] = 0.0
    np.cumsum(widths, out=faces[1:])
    faces = bottom + (top - bottom) * faces / faces[-1]
    faces[-1] = top
    return faces


@dataclass
class LayerProfiles:
    """Layer averages of the particles; arrays of one value per layer."""

    solid_fraction: np.ndarray  # [-]
    vel: np.ndarray  # mean streamwise particle velocity [m/s]
    exchange_coefficient: np.ndarray  # momentum exchange coefficient [kg/(m^3 s)]
    drag: np.ndarray  # streamwise drag on the particles per unit volume [N/m^3]
    volume: np.ndarray  # scratch: solid volume of each layer [m^3]

    @classmethod
    def zeros(cls, cells: int) -> LayerProfiles:
        return cls(*(np.zeros(cells) for _ in range(5)))

    def average(self, pos, vel, radius, selected, drag_coef, drag_x, faces, area, layers=None) -> None:
        """The profiles of the particles (kernels/fluid/layer_averaging.py); layers: a Slabs of
        the layers as (n, 1, 1) planes (physics/fluid/poisson.py), this MPI rank's share
        [lo, hi) averaged from the particles given, the others gathered from their ranks."""
        first, last = (0, faces.size - 1) if layers is None else (layers.lo, layers.hi)
        layer_average(
            pos, vel, radius, selected, drag_coef, drag_x, faces, area,
            self.solid_fraction, self.vel, self.exchange_coefficient, self.drag, self.volume, first, last,
        )  # fmt: skip
        if layers is not None and layers.split:  # the four in one message, layer by layer
            profiles = (self.solid_fraction, self.vel, self.exchange_coefficient, self.drag)
            every = np.stack(profiles, axis=1)
            layers.gather(every)
            for column, profile in enumerate(profiles):
                profile[:] = every[:, column]
