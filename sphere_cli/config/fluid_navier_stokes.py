"""`[fluid] model = "navier-stokes"`: the porous (volume-averaged) Navier-Stokes equations on the
regular fluid grid, coupled to the particles (sphere-fluid-particle-interaction.md).

The equations, the discretisation and the choices behind the defaults are in
sphere_cli/kernels/fluid/navier_stokes.py and docs/user-guide.md ("Fluid flow (porous Navier-Stokes)").
"""

from __future__ import annotations

from typing import Annotated, Literal

import numpy as np
from pydantic import Field, model_validator

from .base import Count, Flag, Real, Strict, _default_tag
from .drag import DragConfig
from .expression import ExpressionText
from .fluid_common import CouplingConfig, NoFlowBoundary, PressureBoundary, RankSplitCells
from .fluid_grid import FluidGridConfig, follow_problems, grid_centres


class NoSlipNoFlow(NoFlowBoundary):
    """A closed face; optionally no slip along it."""

    no_slip: Flag = Field(
        False,
        description="The velocity along the boundary vanishes there too (otherwise free slip) [-].",
    )


class NoSlipPressure(PressureBoundary):
    """An open face at a prescribed pressure; optionally no slip along it."""

    no_slip: Flag = Field(
        False,
        description="The velocity along the boundary vanishes there (otherwise free slip) [-].",
    )


class NoSlipVelocity(Strict):
    """A face through which the fluid enters or leaves at a prescribed rate (give velocity or
    flux); optionally no slip along it. The other boundary must then be open (pressure)."""

    type: Literal["velocity"] = "velocity"
    velocity: Real | None = Field(
        None,
        description=(
            "Superficial velocity through the face along +z, the volume flux per unit area "
            "(positive upward: an inflow at the bottom, an outflow at the top) [m/s]. Exclusive "
            "with flux."
        ),
    )
    flux: Real | None = Field(
        None,
        description=(
            "Volume flux through the whole face along +z (positive upward) [m^3/s]. Exclusive with velocity."
        ),
    )
    no_slip: Flag = Field(
        False,
        description="The velocity along the boundary vanishes there (otherwise free slip) [-].",
    )

    @model_validator(mode="after")
    def _one_way(self):
        if (self.velocity is None) == (self.flux is None):
            raise ValueError("give either velocity [m/s] or flux [m^3/s], one of them")
        return self

    def superficial(self, area: float) -> float:
        """The superficial velocity through a face of this area [m^2] -> [m/s]."""
        return self.velocity if self.velocity is not None else self.flux / area


Boundary = Annotated[NoSlipNoFlow | NoSlipPressure | NoSlipVelocity, Field(discriminator="type")]


class PressureSolverConfig(Strict):
    """Solver of the pressure equation of every fluid step."""

    method: Literal["pcg", "jacobi"] = Field(
        "pcg",
        description=(
            '"pcg": conjugate gradient preconditioned with a multigrid V-cycle (the diagonal on a '
            "grid that does not halve or has fewer than 4096 cells; physics/fluid/poisson.py), "
            'fast; "jacobi": the reference\'s '
            "Jacobi iteration, kept to compare (needs far more iterations) [-]."
        ),
    )
    tolerance: Real = Field(
        1e-10,
        gt=0,
        lt=1,
        description="Stop when ||b - A x|| / ||b|| of the pressure equation is at most this [-].",
    )
    max_iterations: Count = Field(
        100_000,
        ge=1,
        description="A solve that has not converged after this many iterations stops the run (exit 70) [-].",
    )
    rank_split_cells: RankSplitCells = 4096


Components = tuple[ExpressionText, ExpressionText, ExpressionText]


class InitialFluidFields(Strict):
    """The fluid at the start, instead of at rest under the hydrostatic pressure: expressions of
    position or an HDF5 file of the grid's values."""

    velocity: Components | None = Field(
        None,
        description=(
            "Interstitial velocity (x, y and z components) as expressions of x, y, z [m], e.g. "
            '["1e-3*sin(2*pi*x/0.01)", "0", "0"]: numbers, + - * / ^, parentheses, sin, cos, exp, '
            "pi; evaluated where each component lives, on the cell faces normal to it; a no-flow "
            "or prescribed-velocity boundary keeps its own value [m/s]."
        ),
    )
    pressure: ExpressionText | None = Field(
        None,
        description=(
            "Pressure as an expression of x, y, z [m] at the cell centres (default: hydrostatic, "
            "referred to the top if it is a pressure boundary, else the bottom) [Pa]."
        ),
    )
    file: str | None = Field(
        None,
        description=(
            "HDF5 file (relative paths from the case file's folder) with any of the datasets "
            "velocity_x (nx, ny, nz) on the x faces (face i at x = i dx), velocity_y (nx, ny, nz) on "
            "the y faces, velocity_z (nx, ny, nz+1) on the z faces (face k at z = k dz, 0 the "
            "bottom), in m/s, and pressure (nx, ny, nz) at the cell centres, in Pa, x, y, z of the "
            "fluid grid from its lower corner. Exclusive with velocity and pressure."
        ),
    )

    @model_validator(mode="after")
    def _one_way(self):
        if self.file is not None and (self.velocity is not None or self.pressure is not None):
            raise ValueError(
                "give the initial fields either as expressions (velocity, pressure) or in a file"
            )
        return self


class BodyForceField(Strict):
    """A body acceleration that varies in space, acting on the fluid besides gravity (e.g. a
    forcing that drives a flow in a periodic box): expressions of position or an HDF5 file."""

    acceleration: Components | None = Field(
        None,
        description=(
            "Acceleration (x, y and z components) as expressions of x, y, z [m], evaluated on the "
            "faces of each component (the syntax of fluid.initial.velocity) [m/s^2]."
        ),
    )
    file: str | None = Field(
        None,
        description=(
            "HDF5 file (relative paths from the case file's folder) with the datasets "
            "acceleration_x (nx, ny, nz), acceleration_y (nx, ny, nz), acceleration_z (nx, ny, nz+1) "
            "on the faces, as fluid.initial.file's velocity, in m/s^2. Exclusive with acceleration."
        ),
    )

    @model_validator(mode="after")
    def _one_way(self):
        if (self.acceleration is None) == (self.file is None):
            raise ValueError(
                "give the body force either as acceleration expressions or as a file, one of them"
            )
        return self


class FixedBed(Strict):
    """A porous bed held in place, given by its porosity instead of by particles (a case without
    particles): the fluid takes the cell-averaged drag of fluid.drag.law on it, implicitly."""

    porosity: Real | ExpressionText | None = Field(
        None,
        description=(
            "Porosity of the bed's cells: a number, or an expression of x, y, z [m] at the cell "
            'centres (the syntax of fluid.initial.velocity), e.g. "0.4 + 0.1*sin(2*pi*x/0.01)"; '
            "between fluid.drag.porosity_floor and 1 [-]."
        ),
    )
    file: str | None = Field(
        None,
        description=(
            "HDF5 file (relative paths from the case file's folder) with the dataset porosity "
            "(nx, ny, nz) at the cell centres, between fluid.drag.porosity_floor and 1. Exclusive "
            "with porosity."
        ),
    )
    diameter: Real = Field(gt=0, description="Grain diameter d of the bed, for the drag law [m].")
    lower: Real | None = Field(
        None, description="The bed holds the cells whose centre is at or above this z (default: all) [m]."
    )
    upper: Real | None = Field(
        None, description="... and at or below this z (default: all); elsewhere the porosity is 1 [m]."
    )

    @model_validator(mode="after")
    def _one_way(self):
        if (self.porosity is None) == (self.file is None):
            raise ValueError(
                "give the bed's porosity either as porosity (a number or an expression) or as a file"
            )
        if self.lower is not None and self.upper is not None and not self.lower < self.upper:
            raise ValueError(f"lower = {self.lower} must be below upper = {self.upper}")
        return self


def z_cells_problem(shape) -> str | None:
    """What is wrong with a grid of `shape` cells for this fluid (None: nothing)."""
    return "the fluid grid needs at least 2 cells along z" if shape[2] < 2 else None


class NavierStokesFluid(Strict):
    """A Newtonian fluid filling the pores: porous Navier-Stokes on the fluid grid, x and y
    periodic, z bounded by the bottom and top boundaries."""

    model: Literal["navier-stokes"] = Field(description="Selects this fluid model.")
    grid: FluidGridConfig = Field(default_factory=FluidGridConfig, description="The fluid grid.")
    density: Real = Field(1000.0, gt=0, description="Fluid density rho [kg/m^3].")
    viscosity: Real = Field(1e-3, gt=0, description="Dynamic viscosity mu [Pa s].")
    formulation: Literal["A", "B"] = Field(
        "A",
        description=(
            '"A": the pressure acts in both phases (momentum -phi grad p; Zhu et al. 2007 model A, '
            'the older sphere page); "B": in the fluid only (momentum -grad p; model B, the newer '
            "page). Default A: it holds for unsteady and non-uniform flow, while B is only "
            "conditionally valid (Zhou et al. 2010, J. Fluid Mech. 661) [-]."
        ),
    )
    old_pressure_weight: Real = Field(
        0.0,
        ge=0,
        le=1,
        description=(
            "Weight of the old pressure in the predictor (Langtangen et al. 2002): 0 is Chorin's "
            "projection, where every step solves for the whole pressure, so solver tolerances "
            "never accumulate in it (default); 1 is the incremental form [-]."
        ),
    )
    bottom: Boundary = Field(
        default_factory=NoSlipNoFlow, description="Boundary at the lower z face of the box."
    )
    top: Boundary = Field(
        default_factory=NoSlipPressure,
        description="Boundary at the upper z face of the box (default: open at 0 Pa).",
    )
    solver: PressureSolverConfig = Field(
        default_factory=PressureSolverConfig, description="Solver of the pressure equation."
    )
    coupling: CouplingConfig = Field(
        default_factory=CouplingConfig, description="Fluid steps against DEM steps (default: steps = 1)."
    )
    drag: DragConfig = Field(
        default_factory=DragConfig, description="Momentum exchange between particles and fluid."
    )
    initial: InitialFluidFields = Field(
        default_factory=InitialFluidFields,
        description="The fluid at the start (default: at rest, hydrostatic pressure).",
    )
    body_force: BodyForceField | None = Field(
        None, description="A body acceleration field on the fluid besides gravity (default: none)."
    )
    bed: FixedBed | None = Field(
        None,
        description="A porous bed held in place, given by its porosity (a case without particles).",
    )
    max_speed: Real | None = Field(
        None,
        gt=0,
        description=(
            "Largest fluid speed expected [m/s]: the advective limit sum |u_i| dt_f/dx_i <= 1/2 is "
            'then checked before the run (and honoured by dt = "auto"). Whether given or not, '
            "the run stops (exit 70) naming the cell if the fluid ever exceeds that limit."
        ),
    )

    @model_validator(mode="before")
    @classmethod
    def _default_tags(cls, data):
        data = _default_tag(data, "bottom", "type", "no-flow")
        return _default_tag(data, "top", "type", "pressure")

    @model_validator(mode="after")
    def _an_open_face_with_a_prescribed_flow(self):
        kinds = {self.bottom.type, self.top.type}
        if "velocity" in kinds and "pressure" not in kinds:
            raise ValueError(
                'a boundary of type "velocity" needs the other one of type "pressure": with both '
                "faces closed or prescribed, the flow in need not match the flow out"
            )
        return self

    def case_problems(self, case, shape, count: int | None) -> list[tuple[tuple, str]]:
        """What this fluid requires of the rest of the case (config/consistency.py): x and y
        periodic, z bounded; a top wall to follow, through an open top; a bed's rows of cells.
        shape: the grid's cells, None where they depend on radii read from a placement file (the
        build checks the grid then); count: the particles' (unused)."""
        problems = follow_problems(self.grid, case)
        periodic = case.domain.periodic
        if not (periodic[0] and periodic[1]) or periodic[2]:
            problems.append(
                (
                    ("domain", "periodic"),
                    "the Navier-Stokes fluid needs x and y periodic and z not periodic (its bottom and "
                    "top boundaries are the box's z faces): periodic = [true, true, false]",
                )
            )
        if self.grid.follow_top_wall and not isinstance(self.top, PressureBoundary):
            problems.append(
                (
                    ("fluid", "top", "type"),
                    f'"{self.top.type}" cannot be used with fluid.grid.follow_top_wall = true: the fluid '
                    'must be free to leave or enter through the moving top; use type = "pressure"',
                )
            )
        if shape is None:
            return problems
        if problem := z_cells_problem(shape):
            problems.append((("fluid", "grid"), problem))
        bed = self.bed
        if bed is not None:
            z = grid_centres(case.domain.lower, case.domain.upper, shape)[2]
            above = z >= bed.lower if bed.lower is not None else True
            below = z <= bed.upper if bed.upper is not None else True
            if not np.logical_and(above, below).any():
                problems.append(
                    (
                        ("fluid", "bed"),
                        f"no cell centre lies between lower and upper (centres at z = {z[0]:.6g} .. "
                        f"{z[-1]:.6g} m, {shape[2]} along z)",
                    )
                )
        return problems
