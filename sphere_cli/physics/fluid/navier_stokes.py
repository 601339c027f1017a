"""Porous Navier-Stokes fluid (`[fluid] model = "navier-stokes"`): the fluid state on the
staggered grid, one fluid step (predictor, pressure equation through the shared Poisson solver,
correction; equations in kernels/fluid/navier_stokes.py), its stability limits, and the plug-in
that couples it to the DEM loop.

NavierStokesSolver advances a NavierStokesState and knows nothing of particles, so the
fluid-alone checks (tests/physics/test_fluid_navier_stokes.py) drive it directly. NavierStokes
(FluidModule) adds the particles: porosity from physics/fluid/porosity.py, the interaction force
from physics/fluid/drag.py (which reads the cell-centred fs.v and fs.grad_p and writes the cell
fields fs.f_i and fs.k_drag; the fluid step takes their means on the faces), and the coupling
schedule.
"""

from __future__ import annotations

import copy
import math
import types
import warnings
from dataclasses import dataclass

import numpy as np

from ...config.fluid_common import NoFlowBoundary, PressureBoundary
from ...config.fluid_navier_stokes import NavierStokesFluid, NoSlipVelocity, z_cells_problem
from ...errors import NumericalError
from ...kernels.fluid import navier_stokes as navier_stokes_kernels
from ...kernels.fluid.drag import drag_steps, drag_steps_serial, rank_drag_steps, rank_drag_steps_serial
from ...kernels.fluid.navier_stokes import (
    cell_velocity,
    continuity_error,
    first_unstable,
    max_courant,
    moving_cell_rate,
    predict,
    pressure_gradient,
    top_outflow,
)
from ...kernels.fluid.porosity import rate_in_grains_frame
from ..fluid_plugin import GRID_ON_GPU, MOVING_GRID_SPACING, FluidModule, GpuSteps
from .drag import FluidParticleDrag
from .fields import cell_expression, face_expressions, face_shape, read_face_fields, read_grid_file
from .fixed_bed import FixedBed
from .grid import FluidGrid, fluid_grid, top_wall_index, wall_cells
from .poisson import PoissonResult, PoissonSolver, preconditioner_for
from .porosity import Porosity
from .step_place import FieldsOnProcessor


@dataclass
class NavierStokesState:
    """Fluid fields on the staggered grid (C order; kernels/fluid/navier_stokes.py says which
    face is which): the velocity on the cell faces, everything else at the cell centres."""

    v_face: np.ndarray  # (nx,ny,nz+1,3) [m/s] interstitial fluid velocity, component c on the c faces
    v: np.ndarray  # (nx,ny,nz,3) [m/s] its cell-centred value (the faces' mean flux / phi)
    p: np.ndarray  # (nx,ny,nz) [Pa] pressure
    grad_p: np.ndarray  # (nx,ny,nz,3) [Pa/m] gradient of p at the cell centres (central differences)
    porosity: np.ndarray  # (nx,ny,nz) [-]
    porosity_rate: np.ndarray  # (nx,ny,nz) [1/s] d porosity/dt
    f_i: np.ndarray  # (nx,ny,nz,3) [N/m^3] force density on the particles the next step takes
    k_drag: np.ndarray  # (nx,ny,nz) [kg/(m^3 s)] its derivative with respect to the fluid v
    f_exchange: np.ndarray  # (nx,ny,nz,3) [N/m^3] f_i + k_drag (v_new - v_old) of the last step
    acceleration: np.ndarray  # (nx,ny,nz+1,3) [m/s^2] body acceleration on the faces (gravity)
    # scratch of the fluid step (not state)
    v_star: np.ndarray  # (nx,ny,nz+1,3)
    v_old: np.ndarray  # (nx,ny,nz+1,3) the face velocities before the correction
    edges: np.ndarray  # (nx,ny,nz+1,3) the porosity of the cell edges
    flux: np.ndarray  # (nx,ny,nz+2,3,3) the advective fluxes through the faces' control volumes
    normal: np.ndarray  # (nx,ny,nz+2,3) the viscous normal stresses at the cell centres
    shear: np.ndarray  # (nx,ny,nz+1,3) the viscous shear stresses at the edges
    mobility: np.ndarray  # (nx,ny,nz+1,3)
    rhs: np.ndarray
    eps: np.ndarray
    zero: np.ndarray
    ax: np.ndarray
    ay: np.ndarray
    az: np.ndarray
    steps: int = 0  # fluid steps taken
    iterations: int = 0  # of the last pressure solve
    residual: float = 0.0  # relative residual of the last pressure solve
    # a grid following the top wall: its height at the last step [m], and the fluid volume that
    # has left through its top face (relative to the moving face) since the start [m^3]
    height: float = 0.0
    outflow: float = 0.0

    PROGNOSTIC = ("v_face", "v", "p", "grad_p", "porosity", "porosity_rate", "f_i", "k_drag", "f_exchange")
    SCALARS = ("steps", "iterations", "residual")
    MOVING_GRID = ("height", "outflow")


# Largest advective Courant number sum |u_a| dt/dx_a of a fluid step: the limited (TVD) advection
# with forward Euler stays bounded up to 1/2 (kernels/fluid/navier_stokes.py, module docstring).
COURANT_LIMIT = 0.5

# Cells a particle may cross in one fluid step. The coupling takes each particle's drag from
# the cell its centre is in and the porosity's rate from its move over the fluid step: a
# particle that skips cells leaves them untouched. dt = "auto" keeps the fastest settling
# particle within half a cell a fluid step; a run stops where any particle moves a whole cell.
CROSSING_AUTO = 0.5
CROSSING_LIMIT = 1.0

# the fields a fluid step reads of the state, and those it writes there (the rest is scratch)
STEP_INPUTS = ("v_face", "p", "porosity", "porosity_rate", "f_i", "k_drag", "acceleration")
STEP_OUTPUTS = ("v_face", "v", "p", "grad_p", "f_exchange")


class NavierStokesSolver:
    """One fluid step of the porous Navier-Stokes equations on `grid`, for the fluid `config`
    under the body acceleration `gravity` (3,) [m/s^2].

    With config.grid.follow_top_wall the grid's height may change between steps: resize(H) to
    the new height first (then measure the porosity on the new cells), and step() takes the
    moving grid's terms (kernels/fluid/navier_stokes.py) from the height of the last step, fs.height,
    to H."""

    def __init__(self, config: NavierStokesFluid, grid: FluidGrid, gravity):
        self.config = config
        self.grid = grid
        # where the step's fields are (device_fields.py FieldsOnGpu: on a GPU)
        self.on = FieldsOnProcessor(navier_stokes_kernels)
        self.follows = bool(config.grid.follow_top_wall)
        self.height = grid.height  # of the grid now [m]
        self.spacing = np.ascontiguousarray(grid.spacing, dtype=np.float64)
        self.gravity = np.asarray(gravity, dtype=np.float64).copy()
        self.rho = float(config.density)
        self.mu = float(config.viscosity)
        self.old_pressure_weight = float(config.old_pressure_weight)  # beta of the kernels
        self.pressure_in_solid = config.formulation == "A"
        self.boundaries = (config.bottom, config.top)
        self.bc_sign = np.ones((2, 3))
        for row, b in enumerate(self.boundaries):
            if isinstance(b, NoFlowBoundary):
                self.bc_sign[row, 2] = -1.0
            if b.no_slip:
                self.bc_sign[row, :2] = -1.0
        # 1 prescribed pressure, 2 prescribed velocity, 0 no flow (kernels/fluid/navier_stokes.py)
        self.p_kind = np.array(
            [
                1 if isinstance(b, PressureBoundary) else (2 if isinstance(b, NoSlipVelocity) else 0)
                for b in self.boundaries
            ],
            dtype=np.int64,
        )
        area = float(grid.spacing[0] * grid.spacing[1] * grid.shape[0] * grid.shape[1])
        self.inflow = np.array(
            [b.superficial(area) if isinstance(b, NoSlipVelocity) else 0.0 for b in self.boundaries]
        )
        if self.follows and self.p_kind[1] != 1:
            raise ValueError("a grid that follows the top wall needs a prescribed-pressure top boundary")
        kinds = ["dirichlet" if k == 1 else "no-flux" for k in self.p_kind]
        solver = config.solver
        self.poisson = PoissonSolver(
            grid, kinds[0], kinds[1], solver.method, solver.tolerance, solver.max_iterations,
            preconditioner_for(grid), solver.rank_split_cells,
        )  # fmt: skip
        self.p_bound = np.zeros(2)  # boundary pressures at the new time [Pa]
        self.p_old = np.zeros(2)  # and at the old time [Pa]
        self.eps_bound = np.zeros(2)  # and of eps = p_new - beta p_old [Pa]

    # -- state ---------------------------------------------------------------------------------

    def allocate(self) -> NavierStokesState:
        """Fluid at rest, porosity 1, no particles, pressure 0 (initial_pressure() sets it), the
        body acceleration gravity on every face."""
        shape = tuple(self.grid.shape)
        vec = (*shape, 3)
        faces = (shape[0], shape[1], shape[2] + 1, 3)
        ax, ay, az = self.poisson.face_arrays()
        acceleration = np.zeros(faces)
        acceleration[...] = self.gravity
        return NavierStokesState(
            v_face=np.zeros(faces),
            v=np.zeros(vec),
            p=np.zeros(shape),
            grad_p=np.zeros(vec),
            porosity=np.ones(shape),
            porosity_rate=np.zeros(shape),
            f_i=np.zeros(vec),
            k_drag=np.zeros(shape),
            f_exchange=np.zeros(vec),
            acceleration=acceleration,
            v_star=np.zeros(faces),
            v_old=np.zeros(faces),
            edges=np.zeros(faces),
            flux=np.zeros((shape[0], shape[1], shape[2] + 2, 3, 3)),
            normal=np.zeros((shape[0], shape[1], shape[2] + 2, 3)),
            shear=np.zeros(faces),
            mobility=np.zeros(faces),
            rhs=np.zeros(shape),
            eps=np.zeros(shape),
            zero=np.zeros(shape),
            ax=ax,
            ay=ay,
            az=az,
            height=self.height,
        )

    def face_coordinates(self, c: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Where the faces of velocity component c (0, 1, 2) are: x, y, z [m] of shapes (nx,1,1),
        (1,ny,1), (1,1,nz) (nz+1 z faces for c = 2), broadcasting to that component's faces."""
        g = self.grid
        axes = []
        for a in range(3):
            n = g.shape[a] + (1 if a == 2 == c else 0)
            offset = 0.0 if a == c else 0.5
            shape = [1, 1, 1]
            shape[a] = n
            axes.append((g.origin[a] + (np.arange(n) + offset) * g.spacing[a]).reshape(shape))
        return axes[0], axes[1], axes[2]

    def set_velocity(self, fs: NavierStokesState, components) -> None:
        """Set the face velocities from three values or arrays broadcasting to each component's
        faces (face_coordinates), keeping v_z = 0 on a no-flow boundary, and the cell velocities
        (with fs.porosity as it is now; the exchange fs.f_exchange of a fluid at rest)."""
        nz = self.grid.shape[2]
        fs.v_face[...] = 0.0
        for c, value in enumerate(components):
            layers = nz + 1 if c == 2 else nz
            fs.v_face[:, :, :layers, c] = value
        for row, k in ((0, 0), (1, nz)):
            if self.p_kind[row] != 1:  # a no-flow or prescribed-velocity face keeps its value
                fs.v_face[:, :, k, 2] = self.inflow[row] / fs.porosity[:, :, 0 if row == 0 else nz - 1]
        np.copyto(fs.v_old, fs.v_face)
        cell_velocity(fs.v_face, fs.v_old, fs.porosity, fs.f_i, fs.k_drag, self.p_kind, fs.v, fs.f_exchange)

    def update_pressure_gradient(self, fs: NavierStokesState, time: float) -> None:
        """fs.grad_p from fs.p, with the boundary pressures at `time` [s] (after setting fs.p)."""
        self.boundary_pressure(time, self.p_bound)
        pressure_gradient(fs.p, self.spacing, self.p_kind, self.p_bound, fs.grad_p)

    def resize(self, height: float) -> None:
        """Stretch the grid along z to `height` [m] (a grid following the top wall)."""
        self.height = float(height)
        self.grid.set_height(self.height)
        self.poisson.update_spacing()

    def stretch(self, fs: NavierStokesState, dt: float) -> float:
        """(V_new - V_old) / (V_new dt) [1/s] of every cell of a grid following the top wall over
        the fluid step from fs.height to the height of the last `resize`; 0 on a fixed grid."""
        return (self.height - fs.height) / (self.height * dt) if self.follows else 0.0

    def boundary_pressure(self, time: float, out: np.ndarray) -> np.ndarray:
        """Pressures of the bottom and top boundaries at `time` (0 where no-flow) [Pa]."""
        for row, b in enumerate(self.boundaries):
            out[row] = b.value(time) if isinstance(b, PressureBoundary) else 0.0
        return out

    def initial_pressure(self, fs: NavierStokesState, time: float) -> None:
        """Hydrostatic pressure p = p_ref + rho g_z (z - z_ref), referred to the top boundary if it
        has a prescribed pressure, else the bottom one, else zero at mid-height; its gradient."""
        g = self.grid
        z = g.centres(2)
        bottom_z, top_z = g.origin[2], g.origin[2] + g.shape[2] * g.spacing[2]
        self.boundary_pressure(time, self.p_bound)
        if self.p_kind[1] == 1:
            z_ref, p_ref = top_z, self.p_bound[1]
        elif self.p_kind[0] == 1:
            z_ref, p_ref = bottom_z, self.p_bound[0]
        else:
            z_ref, p_ref = 0.5 * (bottom_z + top_z), 0.0
        fs.p[...] = (p_ref + self.rho * self.gravity[2] * (z - z_ref))[None, None, :]
        pressure_gradient(fs.p, self.spacing, self.p_kind, self.p_bound, fs.grad_p)

    # -- the fluid step ------------------------------------------------------------------------

    def step(self, fs: NavierStokesState, time: float, dt: float) -> PoissonResult:
        """Advance the fluid from `time` to `time + dt` [s] with the porosity, its rate and the
        interaction force already in fs."""
        return self.on.run(lambda: self._step(fs, time, dt))

    def _step(self, fs: NavierStokesState, time: float, dt: float) -> PoissonResult:
        rho, beta, solid = self.rho, self.old_pressure_weight, self.pressure_in_solid
        on, k = self.on, self.on.kernels
        old = on.small(self.boundary_pressure(time, self.p_old))
        spacing, bc_sign, p_kind, inflow = (
            on.small(a) for a in (self.spacing, self.bc_sign, self.p_kind, self.inflow)
        )
        work = on.fields(fs)  # fs, or its fields on the GPU
        stretch = self.stretch(fs, dt)
        k.edge_porosity(work.porosity, work.edges)
        # split across MPI ranks with the pressure solve (its slabs of x planes), the prediction
        # takes the rank's planes, from the stresses and fluxes of those and the plane either side
        slabs = self.poisson.slabs
        lo, hi = slabs.lo, slabs.hi
        wide = (lo, hi)
        if slabs.split and lo < hi:
            wide = (lo - 1, hi + 1) if hi - lo + 2 <= fs.porosity.shape[0] else (0, fs.porosity.shape[0])
        k.advective_fluxes(work.v_face, work.porosity, work.edges, bc_sign, work.flux, *wide)
        k.viscous_stresses(
            work.v_face, work.porosity, work.edges, spacing, bc_sign, work.normal, work.shear, *wide
        )  # fmt: skip
        k.predict(
            work.v_face, work.p, work.porosity, work.normal, work.shear, work.flux, work.porosity_rate,
            work.f_i, work.k_drag, work.acceleration, spacing, bc_sign, p_kind, old, rho, self.mu, beta,
            solid, dt, inflow, work.v_star, work.mobility, lo, hi,
        )  # fmt: skip
        slabs.gather(work.v_star)
        slabs.gather(work.mobility)
        if stretch != 0.0:
            k.add_grid_motion(
                work.v_face, work.porosity, work.edges, work.k_drag, bc_sign, p_kind, rho, dt, stretch,
                work.v_star,
            )  # fmt: skip
        k.pressure_rhs(work.v_star, work.porosity, work.porosity_rate, spacing, rho, dt, work.rhs)
        if stretch != 0.0:
            k.add_grid_source(work.porosity, work.porosity_rate, rho, dt, stretch, work.rhs)
        k.face_coefficients(work.mobility, work.ax, work.ay, work.az)
        self.boundary_pressure(time + dt, self.p_bound)
        np.multiply(self.p_old, -beta, out=self.eps_bound)
        self.eps_bound += self.p_bound
        # first guess: eps = p_new - beta p_old with p_new ~ p_old
        on.scale(work.p, 1.0 - beta, work.eps)
        result = self.poisson.solve(
            work.eps, work.rhs, work.zero, work.ax, work.ay, work.az, self.eps_bound[0], self.eps_bound[1]
        )
        fs.iterations, fs.residual = result.iterations, result.residual
        if not math.isfinite(result.residual):
            on.results(work, fs, ("v_star",))  # what the message may name
            raise NumericalError(f"at t = {time + dt:.6g} s the fluid step met {self._first_non_finite(fs)}")
        if not result.converged:
            raise NumericalError(
                f"the fluid pressure solve ({self.poisson.describe()}) did not converge in "
                f"{result.iterations} iterations (relative residual {result.residual:.3g}) at "
                f"t = {time + dt:.6g} s; raise fluid.solver.max_iterations or the tolerance, or "
                'use method = "pcg"'
            )
        on.copy(work.v_old, work.v_face)
        k.correct(
            work.v_star, work.eps, work.porosity, work.mobility, spacing, p_kind, on.small(self.eps_bound),
            rho, beta, dt, work.v_face, work.p,
        )  # fmt: skip
        k.cell_velocity(
            work.v_face, work.v_old, work.porosity, work.f_i, work.k_drag, p_kind, work.v, work.f_exchange
        )  # fmt: skip
        k.pressure_gradient(work.p, spacing, p_kind, on.small(self.p_bound), work.grad_p)
        on.results(work, fs)
        if self.follows:
            fs.outflow += dt * top_outflow(fs.v_face, fs.porosity, self.spacing, stretch)
            fs.height = self.height
        fs.steps += 1
        return result

    def _first_non_finite(self, fs: NavierStokesState) -> str:
        """Where the first NaN or infinity of a fluid step's inputs (or, if none, its predicted
        velocity) sits: the quantity, the cell or face, and its value."""
        fields = (  # name, array, unit, on the faces
            ("porosity", fs.porosity, "", False),
            ("porosity rate", fs.porosity_rate, " 1/s", False),
            ("interaction force density", fs.f_i, " N/m^3", False),
            ("drag coefficient", fs.k_drag, " kg/(m^3 s)", False),
            ("velocity", fs.v_face, " m/s", True),
            ("pressure", fs.p, " Pa", False),
            ("body acceleration", fs.acceleration, " m/s^2", True),
            ("predicted velocity", fs.v_star, " m/s", True),
        )
        for name, field, unit, on_faces in fields:
            bad = np.flatnonzero(~np.isfinite(field))
            if bad.size:
                index = np.unravel_index(int(bad[0]), field.shape)
                where = self._where(index[:3], index[3] if on_faces else None)
                component = f" {'xyz'[index[3]]}" if field.ndim == 4 else ""
                return f"a non-finite {name}{component} ({field[index]}{unit}) at {where}"
        return "a non-finite pressure equation (residual NaN) with finite inputs"

    def _where(self, cell, face_axis: int | None = None) -> str:
        """Names the fluid cell (i, j, k), or its face of that axis, and where it is."""
        i, j, k = (int(n) for n in cell)
        centre = self.grid.origin + (np.array([i, j, k]) + 0.5) * self.spacing
        place = f"fluid cell ({i}, {j}, {k})"
        if face_axis is not None:
            centre[face_axis] -= 0.5 * self.spacing[face_axis]
            place = f"the {'xyz'[face_axis]} face ({i}, {j}, {k}) of the fluid grid"
        return f"{place} at {tuple(round(float(x), 9) for x in centre)} m"

    def continuity_error(self, fs: NavierStokesState, out: np.ndarray | None = None) -> np.ndarray:
        """dphi + div(phi_f v_f) of every cell after the last step [1/s] (zero up to the
        pressure solver's tolerance on a fixed grid; a grid following the top wall adds its own
        source, kernels/fluid/navier_stokes.py)."""
        out = np.zeros(self.grid.shape) if out is None else out
        continuity_error(fs.v_face, fs.porosity, fs.porosity_rate, self.spacing, out)
        return out

    # -- limits and checks ---------------------------------------------------------------------

    def viscous_limit(self) -> float:
        """Largest stable explicit fluid step for the viscous stress [s]: 1/(2 nu (sum 1/dx_a^2 +
        max 1/dx_a^2)), dx^2/(8 nu) on cubic cells (the normal stress d_c(2 mu d_c v_c) doubles
        one direction's share of dx^2/(6 nu))."""
        inv2 = 1.0 / self.spacing**2
        nu = self.mu / self.rho
        return 1.0 / (2.0 * nu * (inv2.sum() + inv2.max()))

    def advective_limit(self, speed: float) -> float:
        """Largest fluid step with sum |u_a| dt/dx_a <= COURANT_LIMIT at the speed `speed` in the
        worst direction [m/s] -> [s]."""
        return COURANT_LIMIT / (speed * float(np.sum(1.0 / self.spacing))) if speed > 0 else math.inf

    def courant(self, fs: NavierStokesState, dt: float) -> float:
        return float(max_courant(fs.v_face, self.spacing, dt))

    def first_unstable(self, fs: NavierStokesState, dt: float) -> str | None:
        """A message naming the first bad cell (a non-finite pressure or face velocity, or a
        Courant number above COURANT_LIMIT), or None."""
        cell, reason, axis, value = first_unstable(fs.v_face, fs.p, self.spacing, dt, COURANT_LIMIT)
        if cell < 0:
            return None
        i, j, k = np.unravel_index(int(cell), self.grid.shape)
        where = self._where((i, j, k))
        values = f"v = {tuple(float(c) for c in fs.v[i, j, k])} m/s, p = {float(fs.p[i, j, k]):.6g} Pa"
        if reason == 1:
            return f"{where} has a non-finite pressure ({float(value)} Pa)"
        if reason == 2:
            return f"{where} has a non-finite velocity {'xyz'[axis]} on a face ({float(value)} m/s)"
        return (
            f"{where} exceeds the advective limit: Courant number sum |v_i| dt_f/dx_i = {value:.3g} > "
            f"{COURANT_LIMIT:g} ({values}); use a smaller dt or fluid.coupling.steps, or set fluid.max_speed"
        )

    def describe(self) -> dict[str, str]:
        c = self.config
        bounds = []
        for name, b in zip(("bottom", "top"), self.boundaries, strict=True):
            if isinstance(b, NoSlipVelocity):
                text = f"superficial velocity {self.inflow[0 if name == 'bottom' else 1]:g} m/s along +z"
            elif isinstance(b, NoFlowBoundary):
                text = "no flow"
            elif b.series is not None:
                text = f"pressure series {b.series}"
            else:
                text = f"pressure {b.pressure:g} Pa"
            if isinstance(b, PressureBoundary) and b.amplitude > 0:
                text += f" + {b.amplitude:g} Pa sin(2 pi t / {b.period:g} s + {b.phase:g})"
            if b.no_slip:
                text += ", no slip"
            bounds.append(f"{name}: {text}")
        return {
            "fluid": (
                f"porous Navier-Stokes, formulation {c.formulation}, rho = {c.density:g} kg/m^3, "
                f"mu = {c.viscosity:g} Pa s, old_pressure_weight = {c.old_pressure_weight:g}"
            ),
            "fluid grid": self.grid.describe()
            + ", periodic in x and y"
            + (", top following the z+ wall" if self.follows else "")
            + self.on.where,
            "fluid boundaries": "; ".join(bounds),
            "pressure solver": self.poisson.describe(),
        }


def rehearse_grid_step(config: NavierStokesFluid, grid: FluidGrid, gravity, dt: float) -> None:
    """One step of a copy of `grid` alone (NavierStokes.grid_step_rehearsal): the fluid at rest
    under its hydrostatic pressure, stirred a little so that the pressure solve iterates, and
    on a grid following the top wall stretched so that the moving grid's terms are taken (and
    the moving cells' porosity rate, which a step with particles takes)."""
    grid = copy.deepcopy(grid)
    solver = NavierStokesSolver(config, grid, gravity)
    fs = solver.allocate()
    solver.initial_pressure(fs, 0.0)
    fs.v_face += np.random.default_rng(0).uniform(-1e-9, 1e-9, fs.v_face.shape)
    if solver.follows:
        solver.resize(1.001 * solver.height)
        moving_cell_rate(fs.porosity, fs.porosity_rate, dt, solver.stretch(fs, dt))
    solver.step(fs, 0.0, dt)
    solver.first_unstable(fs, dt)


class NavierStokes(FluidModule):
    """The porous Navier-Stokes fluid in the DEM loop: x/y periodic box, the grid of
    [fluid.grid], porosity from the particles, drag both ways (physics/fluid/drag.py).

    Schedule: the DEM takes coupling_steps steps in the fluid field of the last fluid step
    (forces() and kick() hand the drag to physics/fluid/drag.py), then after_step() measures the
    porosity where the particles are now, has the drag module gather the force density the fluid
    receives, and advances the fluid by fluid_dt = coupling_steps dt."""

    model = "navier-stokes"
    name = "fluid"
    takes_over = {"kick": "particles"}  # the second half kick with the implicit drag

    def __init__(self, loaded, state):
        super().__init__(loaded, state)
        cfg = loaded.case.fluid
        box = state.box  # x and y periodic, z bounded (config/fluid_navier_stokes.py case_problems)
        self.config = cfg
        self._grid = fluid_grid(cfg.grid, box, state.particles.radius, loaded)
        self.share_threads_by_cells(self._grid.cell_count)
        if problem := z_cells_problem(self._grid.shape):  # cells set by a placement file's radii
            raise loaded.error(("fluid", "grid"), problem)
        self.top_wall = None  # index of the wall the grid's top follows
        if cfg.grid.follow_top_wall:
            self.top_wall = top_wall_index(state)
        self.diameter = 2.0 * float(state.particles.radius.max()) if state.particles.count else 0.0
        # a scene without particles (a fluid alone): never split across MPI ranks, where a rank's
        # step may take none of them and must still meet the others in the porosity's and the
        # exchange's messages
        self.alone = state.particles.count == 0
        self.solver = NavierStokesSolver(cfg, self._grid, box.body_acc)
        # the smallest cell side of the case's grid [m] (before a grid following the top wall is
        # fitted to it, so that dt = "auto" is the same on a resume)
        self.cell = float(self._grid.spacing.min())
        # (its sampling parts from the case's cells, before the grid is fitted to the wall: the
        # same on a resume)
        self.porosity = Porosity(self._grid, state.particles.count)
        if self.top_wall is not None:
            self.solver.resize(self._wall_height(state))
        self.drag = FluidParticleDrag(
            cfg.drag, cfg.density, cfg.viscosity, self._grid, state.particles.count, cfg.formulation == "B"
        )
        self.drag.stretches = self.top_wall is not None
        self.earlier = None  # of a grid following the top wall: _earlier
        self.fs = self.solver.allocate()
        state.fluid = self.fs
        self.loaded = loaded
        self.speed, self.speed_reason = self._particle_speed(state)
        if cfg.body_force is not None:
            self._add_body_force(cfg.body_force)
        self.floor = float(cfg.drag.porosity_floor)
        self.warned = False
        # on a GPU that measures the porosity (gpu_steps): its measurement and count of clamped cells
        self.measured = self.measured_clamped = None
        self.bed = None  # a bed of imposed porosity ([fluid.bed], without particles)
        if cfg.bed is not None:  # a case without particles (config/consistency.py), so a fixed grid
            exchanged = self.drag.pressure_exchanged
            self.bed = FixedBed(cfg.bed, self.solver, cfg.drag, cfg.density, cfg.viscosity, exchanged, loaded)

    def _add_body_force(self, body) -> None:
        """Adds the body-force field of the case to the faces' acceleration (gravity)."""
        key = ("fluid", "body_force")
        if body.file is not None:
            fields = read_face_fields(body.file, "acceleration", self.solver, (*key, "file"), self.loaded)
        else:
            fields = dict(
                enumerate(
                    face_expressions(self.solver, body.acceleration, (*key, "acceleration"), self.loaded)
                )
            )
        for c, value in fields.items():
            self.fs.acceleration[:, :, : face_shape(self._grid, c)[2], c] += value

    def _particle_speed(self, state) -> tuple[float, str]:
        """The speed [m/s] the particles are expected to reach, and what it is: the terminal speed
        in clear fluid of a sphere as wide as the widest moving particle and as far from the
        fluid's density as the farthest (the settling speed grows with both); 0 without moving
        particles; plus fluid.max_speed where the case gives it (particles carried by the flow).
        From the case and what a checkpoint restores unchanged (radii, masses), not from the
        velocities, so that dt = "auto" is the same on a resume; faster particles are the run's
        check to stop (first_unstable)."""
        p = state.particles
        moving = p.inv_mass > 0.0
        if not moving.any():
            return 0.0, ""
        diameter = 2.0 * p.radius[moving]
        density = 1.0 / (p.inv_mass[moving] * math.pi / 6.0 * diameter**3)
        excess = float(np.abs(density - self.config.density).max())
        gravity = float(np.linalg.norm(state.box.body_acc))
        settling = self.drag.settling_speed(float(diameter.max()), excess, gravity)
        reason = (
            f"the terminal speed in clear fluid of the widest moving particle ({diameter.max():.4g} m) "
            f"at the largest density difference ({excess:.4g} kg/m^3), {settling:.4g} m/s"
        )
        if self.config.max_speed is None:
            return settling, reason
        speed = settling + self.config.max_speed
        return speed, f"{reason}, plus fluid.max_speed = {self.config.max_speed:g} m/s"

    def fluid_step_limit(self) -> tuple[float, str]:
        """The fluid step's own limit [s] and what sets it."""
        nu = self.config.viscosity / self.config.density
        limit = self.solver.viscous_limit()
        reason = f"viscous diffusion dx^2/(8 nu) of the fluid step, nu = {nu:.4g} m^2/s"
        if self.speed > 0.0 and CROSSING_AUTO * self.cell / self.speed < limit:
            limit = CROSSING_AUTO * self.cell / self.speed
            reason = (
                f"a particle may cross {CROSSING_AUTO:g} of a cell ({self.cell:.4g} m) a fluid step at "
                f"{self.speed_reason}"
            )
        if self.config.max_speed is not None:
            advective = self.solver.advective_limit(self.config.max_speed)
            if advective < limit:
                limit = advective
                reason = (
                    f"advective limit sum |u| dt/dx <= {COURANT_LIMIT:g} of the fluid step at "
                    f"fluid.max_speed = {self.config.max_speed:g} m/s"
                )
        return limit, reason

    def dt_limit(self) -> tuple[float, str]:
        limit, reason = self.coupling_limit()
        drag_limit, drag_reason = self.drag.dt_limit()
        if drag_limit < limit:
            return drag_limit, drag_reason
        return limit, reason

    def initialize(self, state) -> None:
        """Porosity of the initial packing (no change yet); the fluid at rest under the
        hydrostatic pressure, or the initial fields of [fluid.initial]."""
        fs = self.fs
        self._measure_porosity(state)
        if self.bed is not None:
            self.bed.impose(fs)
        if self.drag.averaged:
            self.drag.start_cell_means(state, fs.porosity)
        fs.porosity_rate[...] = 0.0
        self.solver.initial_pressure(fs, state.clock.time)
        velocity, pressure = self._initial_fields()
        if velocity is not None:
            self.solver.set_velocity(fs, velocity)
        if pressure is not None:
            fs.p[...] = pressure
            self.solver.update_pressure_gradient(fs, state.clock.time)

    def _initial_fields(self) -> tuple[list | None, np.ndarray | None]:
        """The face velocities and cell pressures of [fluid.initial] (None where it gives none),
        from its file, then its expressions."""
        initial, key = self.config.initial, ("fluid", "initial")
        velocity, pressure = None, None
        if initial.file is not None:
            shapes = {f"velocity_{'xyz'[c]}": face_shape(self._grid, c) for c in range(3)}
            shapes["pressure"] = tuple(self._grid.shape)
            found = read_grid_file(initial.file, shapes, (*key, "file"), self.loaded, False)
            if any(name.startswith("velocity") for name in found):
                velocity = [found.get(f"velocity_{'xyz'[c]}", 0.0) for c in range(3)]
            pressure = found.get("pressure")
        if initial.velocity is not None:
            velocity = face_expressions(self.solver, initial.velocity, (*key, "velocity"), self.loaded)
        if initial.pressure is not None:
            pressure = cell_expression(self.solver, initial.pressure, (*key, "pressure"), self.loaded)
        return velocity, pressure

    def read_inputs(self) -> None:
        self._initial_fields()

    def forces(self, state, spring_dt: float | None = None) -> None:
        self.drag.forces(state, self.fs, spring_dt)

    def kick(self, state) -> None:
        self.drag.kick(state, self.fs)

    # the compiled steps with the drag and its kick in the loop (physics/compiled_steps.py)
    steps_kernel = staticmethod(drag_steps)
    serial_steps_kernel = staticmethod(drag_steps_serial)  # on one thread (kernels/serial.py)

    # on MPI ranks (FluidModule.rank_steps_kernels); with the self-induced velocity subtracted,
    # each step's sums of the drag coefficients of a cell's particles over every rank are
    # messages from inside the loop (plan_rank_steps)
    rank_steps_kernels = (rank_drag_steps, rank_drag_steps_serial)

    def force_arguments(self, state) -> tuple:
        return self.drag.loop_arguments(state, self.fs)

    def kick_arguments(self, state) -> tuple:
        return self.drag.kick_arguments(state, self.fs)

    def steps_taken(self, state, done: int) -> None:
        self.drag.steps_taken(state, self.fs, done)

    on_gpu = True
    stability_reads_particles = True  # the fastest particle's cells a fluid step

    own_step_where = GRID_ON_GPU

    def grid_on_gpu(self) -> None:
        from .device_navier_stokes import step_on_gpu

        step_on_gpu(self.solver)

    def grid_device_bytes(self) -> int:
        return self.solver.on.device_bytes() + self.solver.poisson.on.device_bytes()

    def gpu_steps(self, state) -> GpuSteps:
        """The drag on the GPU; on a grid that keeps its cells (no top wall to follow), also the
        porosity and the momentum exchange at the end of each step before a fluid step, so that
        only the grid's fields travel (the moving grid's cells change in this module's step,
        before the porosity: the particles come back for it instead)."""
        if self.top_wall is not None:
            return self.drag.gpu_steps(state, self.fs)
        steps = self.drag.gpu_steps(state, self.fs, self.fluid_dt)
        if self.measured is None:
            self.measured = np.zeros_like(self.fs.porosity)
        shape, drag = self.fs.porosity.shape, self.drag
        means = (
            (drag.cell_velocity.reshape(*shape, 3), drag.cell_diameter.reshape(shape))
            if drag.averaged
            else ()
        )
        particles = state.particles
        measure, self.measured_clamped, sort = self.porosity.gpu_measure(particles, self.measured, *means)
        steps.coupling = [*measure, *steps.coupling]
        steps.coupled += (self.measured, self.measured_clamped)
        steps.scratch += (*sort, self.measured)
        return steps

    def particle_arrays(self, state) -> dict:
        """The drag's arrays per particle (its cell, coefficient, the other forces, the drag of
        the next half kick, the impulse not yet handed to the fluid, the self-induced velocity);
        the fluid's own fields are kept whole on every MPI rank."""
        names = self.drag.PER_PARTICLE + (("disturbance",) if self.drag.corrected else ())
        return {f"drag_{name}": (self.drag, name) for name in names}

    def plan_rank_steps(self, state) -> None:
        self.drag.plan_exchange(state)

    def ghost_arrays(self) -> tuple[str, ...]:
        return ("drag_f_other",)  # every force on the particle but the drag (its contacts)

    def rank_copy(self, whole) -> NavierStokes:
        twin = copy.copy(self)
        twin.drag = copy.copy(self.drag)
        twin.drag.whole = whole
        twin.source = self  # the rank's whole fluid, which takes the fluid's steps (step_on_rank)
        return twin

    def split_grid(self, comm) -> None:
        self.solver.poisson.split(comm)  # the twins' and their source's
        self.porosity.split(comm, self.solver.poisson.slabs)

    def step_on_rank(self, state, whole, held) -> None:
        """after_step on one MPI rank's part (physics/rank_steps.py), on this rank's twin: the
        module it was copied from (the lead's scene's own at rank 0), whose fields are kept whole
        on every rank, takes the step as one rank does, bit for bit on every rank. The porosity
        and the momentum exchange are split on slabs (split_grid): each rank measures and
        settles its slab's cells from the particles (and the drag arrays the step reads) those
        cells can reach, taken from every rank's owners in global order (whole.near), and the
        cells' fields are gathered. The step hands every particle's drag impulse to the fluid:
        the twin's restart from zero."""
        source, p = self.source, state.particles
        drag = source.drag
        read = ("cell_of", "coef", "f_other", "impulse") + (("disturbance",) if drag.corrected else ())
        arrays = (p.pos, p.vel, p.radius, p.inv_mass, *(getattr(self.drag, name) for name in read))
        pos, vel, radius, inv_mass, *taken = whole.near(lambda own: self._reached_by(p.pos[own]), *arrays)
        kept = {name: getattr(drag, name) for name in read}  # the lead's scene's own, at rank 0
        for name, array in zip(read, taken, strict=True):
            setattr(drag, name, array)
        every = types.SimpleNamespace(pos=pos, vel=vel, radius=radius, inv_mass=inv_mass, count=pos.shape[0])
        try:
            source._step(types.SimpleNamespace(particles=every, clock=state.clock, walls=state.walls))
        finally:
            for name, array in kept.items():
                setattr(drag, name, array)
        self.drag.impulse[...] = 0.0

    def _reached_by(self, pos: np.ndarray) -> np.ndarray:
        """Which ranks' cells can reach each of the particles at pos (whole.near): their porosity
        sampling spheres, and the momentum exchange of the cell the particle is in."""
        return self.porosity.needed_by(pos, 0.5 * self.diameter)

    def grid_step_rehearsal(self) -> tuple:
        return predict, rehearse_grid_step, (self.config, self._grid, self.solver.gravity, self.fluid_dt)

    def after_step(self, state) -> None:
        if self.stepped_on_ranks == state.clock.step:
            return  # taken by every MPI rank (step_on_rank), the lead's arrays with it
        self._step(state)

    def _step(self, state) -> None:
        with self.on_its_threads():
            self._grid_step(state)

    def _grid_step(self, state) -> None:
        clock = state.clock
        fs = self.fs
        if self.top_wall is not None:
            self._follow_wall(state)
        if not self.alone:  # without particles the porosity stays 1 and nothing is exchanged
            self.drag.report_below(state, fs)
            # d phi/dt by backward difference over the fluid step (of each cell, moving with the
            # grid); on a grid that moved, in a frame moving with the grains, as Darcy's
            # (rate_in_grains_frame), fed to the solver as the moving cells' rate that makes its
            # source that (moving_cell_rate)
            stretch = self.solver.stretch(fs, self.fluid_dt)
            if stretch:
                earlier, velocity = self._earlier()
                largest = 0.5 * self.diameter
                self.porosity.measure_earlier(state.particles, self.fluid_dt, earlier, largest, velocity)
                np.maximum(earlier, self.floor, out=earlier)
            np.copyto(fs.porosity_rate, fs.porosity)
            self._measure_porosity(state)
            np.subtract(fs.porosity, fs.porosity_rate, out=fs.porosity_rate)
            fs.porosity_rate *= 1.0 / self.fluid_dt
            if stretch:
                np.subtract(fs.porosity, earlier, out=earlier)
                earlier *= 1.0 / self.fluid_dt
                moving_cell_rate(fs.porosity, earlier, self.fluid_dt, stretch)
                top_speed = (self.solver.height - fs.height) / self.fluid_dt
                rate_in_grains_frame(earlier, fs.porosity_rate, velocity, top_speed, False, False)
            self.drag.fluid_forcing(state, fs, self.fluid_dt, self.porosity.slabs)
        elif self.bed is not None:
            self.bed.forcing(fs)
        self.solver.step(fs, (clock.step - self.coupling_steps) * clock.dt, self.fluid_dt)

    def _wall_height(self, state) -> float:
        """Height of the top wall above the grid's bottom [m]."""
        return float(state.walls.coord[self.top_wall]) - float(self._grid.origin[2])

    def _follow_wall(self, state) -> None:
        """Stretch the grid to the top wall, or stop (exit 70) where its cells would no longer
        hold what the porosity estimate (dz at least the largest particle diameter), the moving
        grid's advection (the top moves at most half a cell per fluid step, the fluid's own
        advective limit) or the viscous limit need."""
        nz = self._grid.shape[2]
        height = self._wall_height(state)
        dz_old = self.fs.height / nz
        where = wall_cells(state, self.top_wall, nz, height, self.diameter)
        if not abs(height - self.fs.height) <= 0.5 * dz_old:
            raise NumericalError(
                f"{where}; the wall moved {abs(height - self.fs.height):.4g} m in one fluid step of "
                f"{self.fluid_dt:.4g} s, more than half a cell ({dz_old:.4g} m), the advective limit of "
                "the moving grid's explicit flux; use a smaller dt or fluid.coupling.steps"
            )
        self.solver.resize(height)
        self.porosity.warn_if_outgrown(state.clock.step)
        limit = self.solver.viscous_limit()
        if self.fluid_dt > limit:
            raise NumericalError(
                f"{where}, where the fluid step {self.fluid_dt:.4g} s exceeds the viscous limit "
                f"dx^2/(8 nu) {limit:.4g} s; use a smaller dt or fluid.coupling.steps"
            )

    def _earlier(self) -> tuple[np.ndarray, np.ndarray]:
        """The porosity of the grains a fluid step back and their mean velocity per cell, of a
        grid following the top wall (made when it first moves)."""
        if self.earlier is None:
            shape = self.fs.porosity.shape
            self.earlier = (np.zeros(shape), np.zeros((*shape, 3)))
        return self.earlier

    def _measure_porosity(self, state) -> None:
        """fs.porosity from the particles where they are now, floored at fluid.drag.porosity_floor:
        the fluid divides by phi, and the drag correlations take the same floor."""
        fs = self.fs
        if self.measured is not None:  # measured on a GPU at the end of this step (gpu_steps)
            fs.porosity[...] = self.measured
            self.porosity.report_clamped(int(self.measured_clamped[0]))
        elif self.drag.averaged:
            self.drag.measure_cell_means(state, self.porosity, fs.porosity, 0.5 * self.diameter)
        else:
            self.porosity.measure(state.particles, fs.porosity, largest=0.5 * self.diameter)
        if fs.porosity.min() >= self.floor:
            return
        if not self.warned:
            self.warned = True
            i, j, k = np.unravel_index(int(np.argmin(fs.porosity)), fs.porosity.shape)
            warnings.warn(
                f"step {state.clock.step}: porosity {fs.porosity[i, j, k]:.3g} in fluid cell ({i}, {j}, {k}) "
                f"is below fluid.drag.porosity_floor = {self.floor}; the fluid and the drag use the floor "
                f"there ({int(np.count_nonzero(fs.porosity < self.floor))} cell(s) now, not repeated)",
                RuntimeWarning,
                stacklevel=2,
            )
        np.maximum(fs.porosity, self.floor, out=fs.porosity)

    def prognostic_state(self, state) -> dict[str, np.ndarray]:
        fs = self.fs
        arrays = {name: getattr(fs, name) for name in NavierStokesState.PROGNOSTIC}
        names = NavierStokesState.SCALARS
        if self.top_wall is not None:
            names += NavierStokesState.MOVING_GRID
        for name in names:
            arrays[name] = np.array(getattr(fs, name))
        for name, value in self.drag.prognostic_state().items():
            arrays["drag_" + name] = value
        return arrays

    def restore(self, state, arrays: dict) -> None:
        fs = self.fs
        for name in NavierStokesState.PROGNOSTIC:
            getattr(fs, name)[...] = arrays[name]
        fs.steps = int(arrays["steps"])
        fs.iterations = int(arrays["iterations"])
        fs.residual = float(arrays["residual"])
        if self.top_wall is not None:
            fs.height = float(arrays["height"])
            fs.outflow = float(arrays["outflow"])
            self.solver.resize(fs.height)
        self.drag.restore({name[5:]: value for name, value in arrays.items() if name.startswith("drag_")})

    def first_unstable(self, state) -> str | None:
        found = self.solver.first_unstable(self.fs, self.fluid_dt)
        if found is not None or not state.particles.count:
            return found
        p = state.particles
        speed = np.where(p.inv_mass > 0.0, np.einsum("ij,ij->i", p.vel, p.vel), 0.0)
        i = int(np.argmax(speed))
        cell = float(self._grid.spacing.min())  # of the grid now (it may follow the top wall)
        cells = math.sqrt(float(speed[i])) * self.fluid_dt / cell
        if not cells > CROSSING_LIMIT:  # (a NaN speed is the motion check's to report)
            return None
        where = tuple(float(x) for x in p.pos[i])
        return (
            f"particle {i} at {where} m moves {cells:.3g} cells ({cell:.4g} m) a fluid step at "
            f"{math.sqrt(float(speed[i])):.4g} m/s, more than {CROSSING_LIMIT:g}: its drag and the "
            "porosity it leaves skip cells; use a smaller dt or fluid.coupling.steps, or larger cells"
        )

    def output_fields(self, state) -> dict[str, tuple[np.ndarray, str]]:
        fs = self.fs
        fields = {"pressure": (fs.p, "Pa"), "velocity": (fs.v, "m s-1")}
        if state.particles.count or self.bed is not None:  # else porosity 1, no interaction: not written
            fields.update(porosity=(fs.porosity, "1"), interaction_force=(fs.f_exchange, "N m-3"))
        if self.top_wall is not None:
            fields[MOVING_GRID_SPACING] = (self._grid.spacing, "m")
        return fields

    def grid(self) -> FluidGrid:
        return self._grid

    def observables(self, state) -> dict[str, tuple[float, str]]:
        fs = self.fs
        values = {
            "fluid_max_courant": (self.solver.courant(fs, self.fluid_dt), "1"),
            "pressure_iterations": (float(fs.iterations), "1"),
            "pressure_residual": (float(fs.residual), "1"),
        }
        if self.top_wall is not None:
            values["fluid_grid_height"] = (fs.height, "m")
            values["fluid_pore_volume"] = (float(fs.porosity.sum()) * self._grid.cell_volume, "m3")
            values["fluid_top_outflow_volume"] = (fs.outflow, "m3")
        return values

    def summary(self) -> dict[str, str]:
        facts = self.solver.describe()
        steps = self.coupling_steps
        facts["fluid coupling"] = f"one fluid step of {self.fluid_dt:.4g} s every {steps} DEM step(s)"
        return facts
