"""Case-file section `[fluid]` with `model = "darcy"`:
Pore-pressure diffusion (Darcy flow) coupled to the particles.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field

from .base import Strict


class DarcyFluid(Strict):
    """Pore-pressure diffusion (Darcy flow) coupled to the particles."""

    model: Literal["darcy"] = Field(description="Selects this fluid model.")
