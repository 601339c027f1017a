"""The pore-pressure equation of the Darcy model on a fluid grid, with the porosity given
(kernels/fluid/pore_pressure.py has the equation and its references):

    beta_f phi mu dp/dt = div(k grad p) - mu (dphi/dt + v_p . grad phi) / (1 - phi).

One `advance` clamps the porosity, makes the permeability per cell (Kozeny-Carman or constant)
and its harmonic means on the faces, and solves one backward-Euler step with the shared
symmetric solver (physics/fluid/poisson.py), then the cell-centred gradient and Darcy velocity.
Backward Euler is L-stable: the step is not bound by the explicit diffusion limit
1 / (2 D sum(1/h^2)), D = k / (beta_f phi mu), which is nanoseconds for water in sand, and the
stiff high-frequency modes are damped rather than left ringing (as Crank-Nicolson would at such
steps). Its O(dt) error is what the tests measure.

physics/fluid/darcy.py couples it to the particles (porosity from them, forces on them); the
analytic tests drive it alone.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ...config.fluid_common import PressureBoundary
from ...config.fluid_darcy import ConstantPermeability, DarcyFluid, regions_without_cells
from ...kernels.fluid import pore_pressure as pore_pressure_kernels
from ...kernels.fluid.pore_pressure import first_bad_cell
from .grid import FluidGrid
from .poisson import PoissonResult, PoissonSolver, preconditioner_for
from .step_place import FieldsOnProcessor


def boundary_pressure(boundary, time: float) -> float:
    """Excess pressure held on a "pressure" face at `time` [Pa]; 0 for a no-flow face (unused
    there)."""
    return boundary.value(time) if isinstance(boundary, PressureBoundary) else 0.0


def fixed_pressure_cells(config: DarcyFluid, grid: FluidGrid) -> tuple[np.ndarray, np.ndarray, list[int]]:
    """(mask uint8, value [Pa]) of the cells held at a prescribed pressure (centre inside a
    region; a later region wins), and the indices of the regions that hold no cell centre."""
    fixed = np.zeros(grid.shape, dtype=np.uint8)
    value = np.zeros(grid.shape)
    centres = [grid.centres(a) for a in range(3)]
    for region in config.fixed_pressure:
        bounds = zip(centres, region.lower, region.upper, strict=True)
        inside = [(c >= lo) & (c <= hi) for c, lo, hi in bounds]
        mask = inside[0][:, None, None] & inside[1][None, :, None] & inside[2][None, None, :]
        fixed[mask] = 1
        value[mask] = region.pressure
    return fixed, value, regions_without_cells(config.fixed_pressure, centres)


# the fields a step reads of the state, and those it writes there (the rest is scratch)
STEP_INPUTS = ("pressure", "porosity", "porosity_rate", "particle_velocity")
STEP_OUTPUTS = ("pressure", "porosity_used", "permeability", "gradient", "velocity")
# the state's own arrays and the processor's kernels (poisson.py's face_means with them)
ON_PROCESSOR = FieldsOnProcessor(pore_pressure_kernels)


@dataclass
class DarcyState:
    """The fluid arrays of a Darcy scene (cell-centred, shape (nx, ny, nz) or (nx, ny, nz, 3))."""

    pressure: np.ndarray  # excess pore pressure p [Pa] (prognostic)
    porosity: np.ndarray  # phi from the particles (or prescribed) [-]
    porosity_rate: np.ndarray  # dphi/dt at fixed cell [1/s]
    particle_velocity: np.ndarray  # mean particle velocity per cell [m/s]
    porosity_used: np.ndarray  # phi clamped to [porosity_min, porosity_max] [-]
    source: np.ndarray  # divergence of the skeleton's velocity, div v_s [1/s]
    permeability: np.ndarray  # k [m^2]
    gradient: np.ndarray  # grad p [Pa/m]
    velocity: np.ndarray  # Darcy velocity q / phi, q from the face fluxes [m/s]
    fixed: np.ndarray  # uint8, 1 = cell held at fixed_value
    fixed_value: np.ndarray  # [Pa]
    # scratch of the implicit step
    storage: np.ndarray = field(repr=False, default=None)
    rhs: np.ndarray = field(repr=False, default=None)
    faces: tuple = field(repr=False, default=())
    # diagnostics of the last fluid step
    iterations: int = 0
    residual: float = 0.0
    clamped_cells: int = 0

    SCALARS = ("iterations", "residual", "clamped_cells")


class PorePressure:
    """The pore-pressure equation on a grid: porosity, its rate and the particle velocity are
    inputs (state.porosity, .porosity_rate, .particle_velocity); `advance` takes one implicit
    step and updates pressure, gradient and Darcy velocity."""

    def __init__(self, config: DarcyFluid, grid: FluidGrid, kozeny_carman_coefficient: float | None = None):
        if grid.periodic[2]:
            raise ValueError("the Darcy grid cannot be periodic along z")
        self.config = config
        self.grid = grid
        self.on = ON_PROCESSOR  # where a step's fields are (device_fields.py FieldsOnGpu: on a GPU)
        perm = config.permeability
        if isinstance(perm, ConstantPermeability):
            self.kc = None
        else:
            self.kc = perm.coefficient if perm.coefficient is not None else kozeny_carman_coefficient
            if self.kc is None or not self.kc > 0:
                raise ValueError("the Kozeny-Carman coefficient is needed (no particles to take d from)")
        self.bottom_dirichlet = isinstance(config.bottom, PressureBoundary)
        self.top_dirichlet = isinstance(config.top, PressureBoundary)
        solver = config.solver
        self.solver = PoissonSolver(
            grid,
            bottom="dirichlet" if self.bottom_dirichlet else "no-flux",
            top="dirichlet" if self.top_dirichlet else "no-flux",
            method=solver.method,
            tolerance=solver.tolerance,
            max_iterations=solver.max_iterations,
            preconditioner=preconditioner_for(grid),
            split_cells=solver.rank_split_cells,
        )
        self.periodic = np.asarray(grid.periodic, dtype=np.uint8)
        self.ih = 1.0 / np.asarray(grid.spacing, dtype=np.float64)
        self.ih2 = self.ih**2
        fixed, fixed_value, _ = fixed_pressure_cells(config, grid)
        shape = tuple(grid.shape)
        self.state = DarcyState(
            pressure=np.full(shape, float(config.initial_pressure)),
            porosity=np.full(shape, 0.5 * (config.porosity_min + config.porosity_max)),
            porosity_rate=np.zeros(shape),
            particle_velocity=np.zeros(shape + (3,)),
            porosity_used=np.zeros(shape),
            source=np.zeros(shape),
            permeability=np.zeros(shape),
            gradient=np.zeros(shape + (3,)),
            velocity=np.zeros(shape + (3,)),
            fixed=fixed,
            fixed_value=fixed_value,
            storage=np.zeros(shape),
            rhs=np.zeros(shape),
            faces=self.solver.face_arrays(),
        )
        self.state.pressure[fixed == 1] = fixed_value[fixed == 1]
        self.has_fixed = bool(fixed.any())
        self.explicit = config.time_scheme == "explicit"
        if self.explicit and self.has_fixed:
            raise ValueError("the explicit scheme does not take fixed_pressure regions")

    def update_spacing(self) -> None:
        """Take the grid's current spacing: call after grid.set_height (a grid that follows the
        top wall)."""
        self.ih[:] = 1.0 / self.grid.spacing
        self.ih2[:] = self.ih**2
        self.solver.update_spacing()

    # -- the steps -------------------------------------------------------------------------------

    def update_permeability(self) -> None:
        """porosity -> clamped porosity -> k per cell."""
        self.state.clamped_cells = self._permeability(pore_pressure_kernels, self.state)

    def _permeability(self, k, work) -> int:
        """The clamped porosity and k of work's cells with the kernels k; the cells clamped."""
        c = self.config
        clamped = int(k.clamp_porosity(work.porosity, c.porosity_min, c.porosity_max, work.porosity_used))
        if self.kc is None:
            k.constant_permeability(c.permeability.value, work.permeability)
        else:
            k.kozeny_carman(work.porosity_used, self.kc, work.permeability)
        return clamped

    def advance(self, dt: float, time: float, mean_source: float | None = None) -> PoissonResult:
        """One backward-Euler step of length dt [s] ending at `time` [s] (boundary values taken
        there), from the current inputs. With `mean_source` [1/s], the skeleton's divergence is
        shifted uniformly to have that mean over the grid. Raises ArithmeticError if the solve
        did not converge."""
        return self.on.run(lambda: self._advance(dt, time, mean_source))

    def _advance(self, dt: float, time: float, mean_source: float | None) -> PoissonResult:
        s, c, on = self.state, self.config, self.on
        k = on.kernels
        work = on.fields(s)  # s, or its fields on the GPU
        ih, ih2, periodic = (on.small(a) for a in (self.ih, self.ih2, self.periodic))
        s.clamped_cells = self._permeability(k, work)
        ax, ay, az = work.faces
        k.face_means(work.permeability, self.periodic[0], self.periodic[1], 1, ax, ay, az)
        k.solid_divergence(
            work.porosity_used, work.porosity, work.porosity_rate, work.particle_velocity, ih, periodic,
            work.source,
        )  # fmt: skip
        if mean_source is not None:
            on.shift_to_mean(work.source, mean_source)
        k.backward_euler_system(
            work.pressure, work.porosity_used, work.source, c.compressibility, c.viscosity, dt, work.storage,
            work.rhs,
        )  # fmt: skip
        if self.has_fixed:
            k.eliminate_fixed_cells(
                work.fixed, work.fixed_value, ax, ay, az, ih2, periodic, work.storage, work.rhs
            )  # fmt: skip
            k.cut_fixed_faces(work.fixed, ax, ay, az, periodic)
        bottom, top = self.boundary_values(time)
        if self.explicit:
            self.solver.explicit_step(work.pressure, work.rhs, work.storage, ax, ay, az, bottom, top)
            result = PoissonResult(0, 0.0, True)
        else:
            result = self.solver.solve(work.pressure, work.rhs, work.storage, ax, ay, az, bottom, top)
        s.iterations, s.residual = result.iterations, result.residual
        if result.converged:
            self._gradient(k, work, ih, periodic, time, faces_cut=self.has_fixed)
        on.results(work, s)
        if not result.converged:
            raise ArithmeticError(
                f"the pore-pressure solve did not converge: residual {result.residual:.3g} after "
                f"{result.iterations} iterations (fluid.solver.tolerance = {c.solver.tolerance:g}, "
                f"max_iterations = {c.solver.max_iterations})"
            )
        return result

    def boundary_values(self, time: float) -> tuple[float, float]:
        return boundary_pressure(self.config.bottom, time), boundary_pressure(self.config.top, time)

    def update_gradient(self, time: float, faces_cut: bool = True) -> None:
        """grad p and the Darcy velocity from the current pressure and permeability (boundary
        values at `time`)."""
        self._gradient(pore_pressure_kernels, self.state, self.ih, self.periodic, time, faces_cut)

    def _gradient(self, k, work, ih, periodic, time: float, faces_cut: bool) -> None:
        """update_gradient on work's fields with the kernels k (ih, periodic: self's as they take
        them). faces_cut: False where the face arrays already hold the means of the current
        permeability (a step without fixed cells: nothing has written them since)."""
        bottom, top = self.boundary_values(time)
        dirichlet = np.uint8(self.bottom_dirichlet), np.uint8(self.top_dirichlet)
        k.pressure_gradient(work.pressure, ih, periodic, *dirichlet, bottom, top, work.gradient)
        ax, ay, az = work.faces
        if faces_cut:  # the faces again, uncut: a fixed cell exchanges fluid with its neighbours
            k.face_means(work.permeability, self.periodic[0], self.periodic[1], 1, ax, ay, az)
        k.darcy_velocity(
            work.pressure, ax, ay, az, ih, periodic, *dirichlet, bottom, top, work.porosity_used,
            self.config.viscosity, work.velocity,
        )  # fmt: skip

    # -- facts -----------------------------------------------------------------------------------

    def explicit_limit(self) -> float:
        """The explicit (forward Euler) diffusion limit 1 / (2 D_max sum(1/h^2)) of this grid with
        the current permeability [s], D = k / (beta_f phi mu), the sum over the axes with more
        than one cell (a single cell has no neighbour along its axis): what an explicit scheme
        would need and backward Euler does not."""
        s, c = self.state, self.config
        self.update_permeability()
        diffusivity = float(np.max(s.permeability / (c.compressibility * s.porosity_used * c.viscosity)))
        stencil = sum(float(self.ih2[a]) for a in range(3) if self.grid.shape[a] > 1)
        return 1.0 / (2.0 * diffusivity * stencil) if stencil > 0 else math.inf

    def explicit_step_limit(self) -> float:
        """explicit_limit() at the largest diffusivity the clamps allow [s]: D = k/(beta_f phi mu)
        peaks at porosity_max for Kozeny-Carman (k/phi = k_c phi^2/(1 - phi)^2 grows with phi),
        at porosity_min for a constant k. What the explicit scheme's fluid step must stay below
        whatever the particles do."""
        c = self.config
        if self.kc is None:
            diffusivity = c.permeability.value / (c.compressibility * c.porosity_min * c.viscosity)
        else:
            phi = c.porosity_max
            diffusivity = self.kc * phi**2 / (1.0 - phi) ** 2 / (c.compressibility * c.viscosity)
        stencil = sum(float(self.ih2[a]) for a in range(3) if self.grid.shape[a] > 1)
        return 1.0 / (2.0 * diffusivity * stencil) if stencil > 0 else math.inf

    def first_bad_cell(self) -> str | None:
        m = int(first_bad_cell(self.state.pressure))
        if m < 0:
            return None
        cell = np.unravel_index(m, self.grid.shape)
        value = self.state.pressure[cell]
        return f"pore pressure {value} Pa in fluid cell {tuple(int(i) for i in cell)}"
