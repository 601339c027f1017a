"""Case-file section `[fluid]` with `model = "vans1d"`:
A 1D vertical fluid velocity profile (VANS with mixing-length turbulence) coupled to the particles,
for bedload transport.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from .base import Strict


class Vans1dFluid(Strict):
    """A 1D vertical fluid velocity profile (VANS with
    mixing-length turbulence) coupled to the particles, for bedload transport."""

    model: Literal["vans1d"] = Field(description="Selects this fluid model.")
