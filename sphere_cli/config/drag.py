"""The `[fluid.drag]` table of a Navier-Stokes case: which drag law couples particles and fluid.

The laws and their forms are in sphere_cli/kernels/fluid/drag.py; docs/user-guide.md ("Drag and
coupling") explains the choices.
"""

from __future__ import annotations

from typing import Literal

from pydantic import Field, model_validator

from .base import Flag, Real, Strict


class DragConfig(Strict):
    """Fluid-particle momentum exchange: the drag law, the pressure-gradient force, the porosity
    floor of the drag correlations."""

    law: Literal["gidaspow", "di-felice"] = Field(
        "gidaspow",
        description=(
            '"gidaspow": Ergun (1952) for porosity <= 0.8, Wen & Yu (1966) above with the '
            "Schiller-Naumann drag coefficient (0.44 for Re >= 1000), as in Gidaspow (1994); "
            '"di-felice": Di Felice (1994), the law of the original CUDA code of sphere. Each '
            "particle feels the drag of its own velocity and diameter relative to the fluid "
            "velocity and porosity of its cell [-]."
        ),
    )
    averaging: Literal["particle", "cell"] = Field(
        "particle",
        description=(
            '"particle": each particle\'s drag from its own diameter and velocity relative to its '
            'cell\'s fluid; "cell": the cell-averaged drag of the sphere documentation, the force '
            "(1 - phi) k(phi, d, |u - v|) (u - v) of a cell from the mean diameter d and velocity v "
            "of its particles (lens-volume weighted, measured with the porosity at each fluid "
            "step), shared among the particles whose centres lie in it by their volumes [-]."
        ),
    )
    pressure_force: Flag = Field(
        True,
        description=(
            "Add the pressure-gradient force -V_p grad(p) on every particle (with the hydrostatic "
            "pressure in p this is the buoyancy). Off, particles feel drag only: no buoyancy, and "
            "a bed carries only the drag share of the pressure drop [-]."
        ),
    )
    porosity_floor: Real = Field(
        0.1,
        gt=0,
        lt=1,
        description=(
            "Porosity below which the drag correlations take this value instead (Ergun diverges "
            "as porosity -> 0); a warning names the first cell where it happens [-]."
        ),
    )
    self_induced: Literal["subtract", "keep"] = Field(
        "subtract",
        description=(
            '"subtract": each particle feels its cell\'s fluid velocity less its own disturbance of '
            "it (the self-induced velocity of a particle smaller than its cell, estimated from the "
            "grid's response to its drag and screened by the other particles of the cell), so that "
            "a sphere settling alone reaches its terminal velocity on any cell size; "
            '"keep": the cell\'s velocity as it is. Default "subtract" with averaging = '
            '"particle", "keep" with "cell" (a closure on the cell means, which hold every '
            "particle's share) [-]."
        ),
    )

    @model_validator(mode="before")
    @classmethod
    def _default_by_averaging(cls, data):
        if isinstance(data, dict) and "self_induced" not in data:
            data = {**data, "self_induced": "keep" if data.get("averaging") == "cell" else "subtract"}
        return data

    @model_validator(mode="after")
    def _self_induced_needs_particle_drag(self):
        if self.averaging == "cell" and self.self_induced == "subtract":
            raise ValueError(
                'self_induced = "subtract" needs averaging = "particle": the cell-averaged drag is '
                "a closure on the cell's mean velocities, which already hold every particle's share"
            )
        return self
