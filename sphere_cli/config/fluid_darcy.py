"""`[fluid] model = "darcy"`: pore-pressure diffusion in a compressible pore fluid without inertia
(slow seepage, consolidation, pressure forcing), coupled to the particles (physics/fluid/darcy.py).

The unknown is the excess pore pressure p: the pressure above the hydrostatic one of a fluid of
`density` under `domain.gravity`. Every pressure of this table (boundaries, fixed cells,
initial value) is such an excess pressure.
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field, model_validator

from .base import Count, Real, Strict, Vec3, _default_tag
from .fluid_common import CouplingConfig, NoFlowBoundary, PressureBoundary, RankSplitCells
from .fluid_grid import FluidGridConfig, follow_problems, grid_centres

DarcyBoundary = Annotated[PressureBoundary | NoFlowBoundary, Field(discriminator="type")]


class KozenyCarmanPermeability(Strict):
    """k = k_c phi^3 / (1 - phi)^2 per cell (Kozeny-Carman), phi clamped to
    [porosity_min, porosity_max]."""

    model: Literal["kozeny-carman"] = "kozeny-carman"
    coefficient: Real | None = Field(
        None,
        gt=0,
        description=(
            "Kozeny-Carman coefficient k_c. Default: d^2/180 with d the mean particle diameter of "
            "the scene [m^2]."
        ),
    )


class ConstantPermeability(Strict):
    """The same permeability in every cell, whatever the porosity."""

    model: Literal["constant"]
    value: Real = Field(gt=0, description="Permeability k [m^2].")


Permeability = Annotated[KozenyCarmanPermeability | ConstantPermeability, Field(discriminator="model")]


class FixedPressureRegion(Strict):
    """Cells whose centre lies inside an axis-aligned box keep a prescribed excess pressure."""

    lower: Vec3 = Field(description="Lower corner of the region [m].")
    upper: Vec3 = Field(description="Upper corner of the region [m].")
    pressure: Real = Field(description="Excess pore pressure held in these cells [Pa].")

    @model_validator(mode="after")
    def _ordered(self):
        for ax, lo, hi in zip("xyz", self.lower, self.upper, strict=True):
            if not hi > lo:
                raise ValueError(f"upper {ax} ({hi}) must exceed lower {ax} ({lo})")
        return self


class DarcySolver(Strict):
    """The implicit solve of each fluid step (the shared symmetric solver, physics/fluid/poisson.py)."""

    method: Literal["pcg", "jacobi"] = Field(
        "pcg",
        description=(
            'Iterative method: "pcg" (conjugate gradients preconditioned with a multigrid V-cycle '
            "on a grid of 4096 cells or more whose counts halve, else the diagonal) or "
            '"jacobi" (the original sphere\'s iteration, much slower; for comparison).'
        ),
    )
    tolerance: Real = Field(
        1e-8, gt=0, lt=1, description="Stop when ||b - A p|| / ||b|| falls below this [-]."
    )
    max_iterations: Count = Field(
        10000, ge=1, description="Iterations after which a solve that has not converged is an error [-]."
    )
    rank_split_cells: RankSplitCells = 4096


class DarcyFluid(Strict):
    """Darcy pore-pressure flow: dp/dt = div(k grad p)/(beta_f phi mu)
    - (dphi/dt + v_p . grad phi)/(beta_f phi (1 - phi)), solved implicitly (backward Euler)."""

    model: Literal["darcy"] = Field(description="Selects this fluid model.")
    grid: FluidGridConfig = Field(default_factory=FluidGridConfig, description="The fluid grid.")
    density: Real = Field(
        1000.0, gt=0, description="Fluid density rho_f (buoyancy and the hydrostatic reference) [kg/m^3]."
    )
    viscosity: Real = Field(1.0e-3, gt=0, description="Dynamic viscosity mu of the fluid [Pa s].")
    compressibility: Real = Field(
        4.5e-10, gt=0, description="Fluid compressibility beta_f (water: 4.5e-10) [1/Pa]."
    )
    permeability: Permeability = Field(
        default_factory=KozenyCarmanPermeability,
        description='Permeability law: model = "kozeny-carman" (default) or "constant".',
    )
    porosity_min: Real = Field(
        0.1,
        gt=0,
        lt=1,
        description=(
            "Cell porosities below this are raised to it in the fluid equations (Kozeny-Carman "
            "vanishes and the storage term degenerates as phi -> 0); clamped cells are counted "
            "in the observable darcy_clamped_cells [-]."
        ),
    )
    porosity_max: Real = Field(
        0.9,
        gt=0,
        lt=1,
        description=(
            "Cell porosities above this are lowered to it (Kozeny-Carman diverges and the source "
            "term 1/(1 - phi) is singular as phi -> 1; the permeability of open fluid is then "
            "k_c porosity_max^3 / (1 - porosity_max)^2) [-]."
        ),
    )
    initial_pressure: Real = Field(0.0, description="Excess pore pressure in every cell at t = 0 [Pa].")
    pressure_force: Literal["seepage", "pressure-gradient"] = Field(
        "seepage",
        description=(
            'Force of the pore fluid on a particle of volume V: "seepage" (default), -V grad p / '
            "(1 - phi), the whole seepage force -grad p per unit volume of the mixture shared among "
            "the grains (Darcy drag plus pressure gradient: the classical critical gradient and "
            'effective stress); "pressure-gradient", -V grad p, the original sphere\'s, a (1 - phi) '
            "fraction of it."
        ),
    )
    top: DarcyBoundary = Field(
        default_factory=PressureBoundary,
        description='Top face (z+): type = "pressure" (default, 0 Pa) or "no-flow".',
    )
    bottom: DarcyBoundary = Field(
        default_factory=NoFlowBoundary,
        description='Bottom face (z-): type = "no-flow" (default) or "pressure".',
    )
    fixed_pressure: list[FixedPressureRegion] = Field(
        default_factory=list,
        description="Regions whose cells hold a prescribed excess pressure, one table per region.",
    )
    coupling: CouplingConfig = Field(
        default_factory=CouplingConfig,
        description="Fluid steps against DEM steps (default: steps = 1); one pressure solve a fluid step.",
    )
    solver: DarcySolver = Field(default_factory=DarcySolver, description="The implicit pressure solve.")
    time_scheme: Literal["implicit", "explicit"] = Field(
        "implicit",
        description=(
            '"implicit" (default): backward Euler, one solve a fluid step, stable at any step; '
            '"explicit": forward Euler (the original sphere\'s explicit scheme), no solve but the fluid '
            "step bound by the diffusion limit 1/(2 D sum 1/h^2), D = k/(beta_f phi mu) at its largest "
            "(nanoseconds for water in sand): for comparison; not with fixed_pressure regions [-]."
        ),
    )

    @model_validator(mode="before")
    @classmethod
    def _default_tags(cls, data):
        data = _default_tag(data, "top", "type", "pressure")
        data = _default_tag(data, "bottom", "type", "pressure")
        return _default_tag(data, "permeability", "model", "kozeny-carman")

    @model_validator(mode="after")
    def _clamps_ordered(self):
        if not self.porosity_min < self.porosity_max:
            raise ValueError(
                f"porosity_min ({self.porosity_min}) must be below porosity_max ({self.porosity_max})"
            )
        return self

    def case_problems(self, case, shape, count: int | None) -> list[tuple[tuple, str]]:
        """What this fluid requires of the rest of the case (config/consistency.py): z bounded; a
        top wall to follow, then neither fixed-pressure regions nor the explicit scheme; a cell
        in every fixed-pressure region. shape: the grid's cells, None where they depend on radii
        read from a placement file (the build checks the regions then); count: the particles'
        (unused)."""
        problems = follow_problems(self.grid, case)
        if case.domain.periodic[2]:
            problems.append(
                (
                    ("domain", "periodic"),
                    "the Darcy model needs a bounded z axis (its top and bottom boundaries); make z "
                    "non-periodic",
                )
            )
        if self.time_scheme == "explicit":
            for key, given in (
                ("fixed_pressure", self.fixed_pressure),
                ("grid.follow_top_wall", self.grid.follow_top_wall),
            ):
                if given:
                    problems.append(
                        (
                            ("fluid", "time_scheme"),
                            f'"explicit" cannot be combined with fluid.{key}: the explicit scheme is '
                            'there to compare with; use time_scheme = "implicit"',
                        )
                    )
        if self.grid.follow_top_wall and self.fixed_pressure:
            problems.append(
                (
                    ("fluid", "fixed_pressure"),
                    "cannot be combined with fluid.grid.follow_top_wall = true: the cells move with the "
                    "wall, and a region of them would not stay where it was given",
                )
            )
        elif shape is not None:
            centres = grid_centres(case.domain.lower, case.domain.upper, shape)
            problems += [
                (("fluid", "fixed_pressure", r), empty_region_problem(shape, centres))
                for r in regions_without_cells(self.fixed_pressure, centres)
            ]
        return problems


def regions_without_cells(regions: list[FixedPressureRegion], centres) -> list[int]:
    """Indices of the fixed-pressure `regions` that hold no cell centre; centres: the centres'
    coordinates along x, y and z [m]."""
    return [
        r
        for r, region in enumerate(regions)
        if not all(
            ((c >= lo) & (c <= hi)).any()
            for c, lo, hi in zip(centres, region.lower, region.upper, strict=True)
        )
    ]


def empty_region_problem(shape, centres) -> str:
    """The message of a fixed-pressure region that holds no cell centre of the grid."""
    nx, ny, nz = shape
    span = ", ".join(f"{'xyz'[a]} = {c[0]:.6g} .. {c[-1]:.6g}" for a, c in enumerate(centres))
    return (
        f"holds no cell centre of the fluid grid ({nx} x {ny} x {nz} cells, centres at {span} m); "
        "widen the region"
    )
