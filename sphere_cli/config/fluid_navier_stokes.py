"""Case-file section `[fluid]` with `model = "navier-stokes"`:
Porous (volume-averaged) Navier-Stokes flow on a regular grid coupled to the particles by drag.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from .base import Strict


class NavierStokesFluid(Strict):
    """Porous (volume-averaged) Navier-Stokes flow on a regular
    grid coupled to the particles by drag."""

    model: Literal["navier-stokes"] = Field(description="Selects this fluid model.")
