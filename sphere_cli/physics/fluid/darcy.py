"""Darcy pore-pressure flow coupled to the particles (`[fluid] model = "darcy"`).

The fluid is the pore-pressure equation of physics/fluid/pore_pressure.py on the shared fluid grid.
Each fluid step (every fluid.coupling.steps DEM steps, after the kick and the clock) measures the
porosity and the mean particle velocity per cell from the particles (physics/fluid/porosity.py),
takes dphi/dt as the backward difference over the fluid step, and solves one implicit step.
The forces hook of every DEM step adds to each particle the seepage force -V grad p / (1 - phi)
and the buoyancy -rho_f V g (kernels/fluid/darcy.py). With `[fluid.grid] follow_top_wall` the
grid's top is the top wall: the cells stretch with it, and an impermeable wall (a "no-flow"
top) is pushed by the pore pressure under it (walls.fluid_force).
"""

from __future__ import annotations

import copy
import logging
import math
import types

import numpy as np

from ...config.fluid_darcy import DarcyFluid, empty_region_problem
from ...errors import NumericalError
from ...kernels.fluid.darcy import add_pressure_forces, push_wall
from ...kernels.fluid.pore_pressure import backward_euler_system
from ...kernels.fluid.porosity import rate_in_grains_frame
from ..fluid_plugin import GRID_ON_GPU, MOVING_GRID_SPACING, FluidModule, GpuSteps
from .grid import FluidGrid, fluid_grid, top_wall_index, wall_cells
from .pore_pressure import PorePressure, fixed_pressure_cells
from .porosity import Porosity

# porosity of the densest packing of equal spheres, 1 - pi / (3 sqrt 2) (FCC): the lowest a bed
# of spheres reaches, where the permeability and so the coupling's time limit are smallest
DENSEST_POROSITY = 0.26
# fraction of the seepage force's relaxation time rho_s k (1 - phi) / mu a fluid step may take
# (Darcy.fluid_step_limit)
COUPLING_FRACTION = 0.2


def rehearse_grid_step(
    config: DarcyFluid, grid: FluidGrid, kozeny_carman: float | None, dt: float, moving: bool
) -> None:
    """One step of the pore pressure on a copy of `grid` alone (Darcy.grid_step_rehearsal), the
    porosity changing a little so that the solve iterates; `moving`: with the mean source of a
    grid following the top wall."""
    pore = PorePressure(config, copy.deepcopy(grid), kozeny_carman)
    s = pore.state
    s.porosity_rate[...] = np.random.default_rng(0).uniform(-1e-9, 1e-9, s.porosity_rate.shape)
    pore.advance(dt, dt, 0.0 if moving else None)


class Darcy(FluidModule):
    """The Darcy fluid of a scene (physics/fluid_plugin.py has the hooks and where they run)."""

    model = "darcy"

    def __init__(self, loaded, state):
        super().__init__(loaded, state)
        config: DarcyFluid = loaded.case.fluid
        # what the fluid requires of the rest of the case is refused before the scene is built
        # (config/fluid_darcy.py case_problems); here what depends on the particles made
        box, particles = state.box, state.particles
        grid = fluid_grid(config.grid, box, particles.radius, loaded)
        # a grid that follows the top wall: the wall bounds the pore fluid (physics/fluid/grid.py)
        self.top_wall = None
        self.diameter = 2.0 * float(particles.radius.max()) if particles.count else 0.0
        if config.grid.follow_top_wall:
            self.top_wall = top_wall_index(state)
            height = self._wall_height(state, grid)
            if not height / grid.shape[2] >= self.diameter:
                raise loaded.error(
                    ("fluid", "grid", "follow_top_wall"),
                    f"the top wall {height:.6g} m above the grid's bottom makes the {grid.shape[2]} cells "
                    f"along z lower than the largest particle diameter {self.diameter:.4g} m that the "
                    "porosity estimate needs; use fewer cells along z",
                )
            grid.set_height(height)
        _, _, empty = fixed_pressure_cells(config, grid)
        if empty:  # cells set by a placement file's radii
            centres = [grid.centres(a) for a in range(3)]
            raise loaded.error(
                ("fluid", "fixed_pressure", empty[0]), empty_region_problem(grid.shape, centres)
            )
        # a scene without particles (fluid only): the porosity of open fluid clamped, porosity_max,
        # that never changes, and no coupling; the Kozeny-Carman coefficient is then given
        # (config/consistency.py)
        self.alone = particles.count == 0
        self.mean_diameter = 0.0 if self.alone else 2.0 * float(np.mean(particles.radius))
        # the coupling's limit is set by the particles that move (fixed ones take no push back)
        moving = particles.inv_mass > 0.0
        volume = 4.0 / 3.0 * np.pi * particles.radius[moving] ** 3
        self.lightest_density = float(np.min(particles.mass[moving] / volume)) if moving.any() else math.inf
        self.pore = PorePressure(config, grid, self.mean_diameter**2 / 180.0 or None)
        self.share_threads_by_cells(grid.cell_count)
        self.porosity = Porosity(grid, particles.count)
        self.porosity_previous = np.zeros(grid.shape)  # phi at the last fluid step [-]
        # on a grid following the top wall: phi of the grains a fluid step back on the cells now
        # (Porosity.measure_earlier), then the rate at points fixed in space [-, then 1/s]
        self.porosity_earlier = np.zeros(grid.shape)
        self.gravity = np.asarray(box.body_acc, dtype=np.float64)
        self.warned_below_min = False  # of cells below porosity_min
        self.logged_above_max = False  # of cells above porosity_max (run.log)
        self.clamped_seen = 0  # the count of clamped cells _warn_clamped last looked at
        # with the particles on a GPU and a grid that keeps its cells: the porosity and mean
        # particle velocity measured there at the end of each step before a fluid step
        # (gpu_steps), and the (1,) count of cells it clamped at 0
        self.measured = self.measured_clamped = None
        self.whole_seepage = np.uint8(config.pressure_force == "seepage")
        # an impermeable top wall takes the pore pressure under it (a permeable one has the same
        # pressure on both faces and carries the effective stress only)
        self.pushes_wall = self.top_wall is not None and not self.pore.top_dirichlet
        self.wall_stiffness = 0.0  # dp/dH of the undrained fluid at the last fluid step [Pa/m]
        self.warned_stiffer = False
        limit = self.wall_stiffness_limit(state)  # what the wall's dt limit counted [N/m]
        self.assumed_wall_stiffness = limit[self.top_wall][0] if limit else math.inf
        state.fluid = self.pore.state

    # -- schedule --------------------------------------------------------------------------------

    def fluid_step_limit(self) -> tuple[float, str]:
        """The smaller of the coupling's limit (_coupling_step_limit) and, with the explicit
        scheme, its diffusion limit."""
        coupling = self._coupling_step_limit()
        if self.pore.explicit:
            diffusion = self.pore.explicit_step_limit()
            if diffusion < coupling[0]:
                return diffusion, (
                    'time_scheme = "explicit": the diffusion limit 1/(2 D sum 1/h^2) at the largest '
                    "D = k/(beta_f phi mu) the porosity clamps allow"
                )
        return coupling

    def _coupling_step_limit(self) -> tuple[float, str]:
        """The implicit diffusion sets no limit; the coupling is explicit. A compacting
        skeleton raises, through the source term, a pressure whose gradient pushes back on the
        grains one fluid step later: in 1D, k dp/dz = -mu v_s, so the seepage force per unit
        volume of solid, -(dp/dz)/(1 - phi), is a drag of relaxation time rho_s k (1 - phi) / mu
        (rho_s k / mu for pressure_force = "pressure-gradient", without the 1/(1 - phi)).
        The limit is COUPLING_FRACTION of that time at its shortest over the porosities the
        model uses, with rho_s the lightest density of the particles that move (fixed ones are
        pushed but do not answer). Kozeny-Carman's k (1 - phi) = k_c phi^3 / (1 - phi) is
        smallest at the lowest porosity (the densest sphere packing, phi = 0.26, or
        porosity_min if higher); a constant k (1 - phi) at the highest, porosity_max. Measured
        on a loose settling bed (tests/physics/test_darcy_coupled.py): with a constant k stable
        at 1.5 of the time at porosity_max = 0.9 and blowing up at 2; with Kozeny-Carman stable
        at 4 of the time at 0.26 (its cells are looser, so more permeable). The fraction keeps
        a margin for beds looser than that one."""
        if self.alone:
            return (
                math.inf,
                "no particles to couple to, and the implicit pore-pressure step is stable at any step",
            )
        if math.isinf(self.lightest_density):
            return math.inf, "no particle moves: the pore pressure pushes on nothing that answers"
        config = self.pore.config
        if self.pore.kc is None:
            phi = config.porosity_max
            k = config.permeability.value
        else:
            phi = max(config.porosity_min, DENSEST_POROSITY)
            k = self.pore.kc * phi**3 / (1.0 - phi) ** 2
        share = 1.0 - phi if self.whole_seepage else 1.0
        factor = " (1 - phi)" if self.whole_seepage else ""
        where = f" at porosity {phi:g}" if self.whole_seepage or self.pore.kc is not None else ""
        limit = COUPLING_FRACTION * self.lightest_density * k * share / config.viscosity
        return limit, (
            f"explicit Darcy coupling: {COUPLING_FRACTION:g} rho_s k{factor} / mu{where}, rho_s = "
            f"{self.lightest_density:.4g} kg/m^3, k = {k:.3g} m^2, mu = {config.viscosity:g} Pa s"
        )

    def _wall_height(self, state, grid: FluidGrid) -> float:
        """Height of the top wall above the grid's bottom [m]."""
        return float(state.walls.coord[self.top_wall]) - float(grid.origin[2])

    def _fit_grid(self, state) -> None:
        """Stretch the grid to the top wall, or stop (exit 70) where its cells would be lower than
        the largest particle diameter, which the porosity estimate needs."""
        grid = self.pore.grid
        height = self._wall_height(state, grid)
        wall_cells(state, self.top_wall, grid.shape[2], height, self.diameter)
        grid.set_height(height)
        self.pore.update_spacing()
        self.porosity.warn_if_outgrown(state.clock.step)

    def _follow_wall(self, state) -> float:
        """Stretch the grid to the top wall (_fit_grid); returns the speed of its top over the
        fluid step [m/s]. Stops (exit 70) where the wall moved more than half a cell in one fluid
        step (as a stage's approach may, which moves it at once): the porosity rate and the
        wall's undrained spring are linear in a small move."""
        grid, clock = self.pore.grid, state.clock
        before = grid.height
        moved = self._wall_height(state, grid) - before
        if not abs(moved) <= 0.5 * before / grid.shape[2]:
            raise NumericalError(
                f"step {clock.step} (t = {clock.time:.6g} s): the top wall moved {abs(moved):.4g} m in one "
                f"fluid step of {self.fluid_dt:.4g} s, more than half a fluid cell "
                f"({before / grid.shape[2]:.4g} m, fluid.grid.follow_top_wall); move it slower (no "
                "approach on a wall the Darcy grid follows) or use a smaller dt or fluid.coupling.steps"
            )
        self._fit_grid(state)
        return (grid.height - before) / self.fluid_dt

    def _undrained_stiffness(self) -> float:
        """dp/dH of the pore fluid without drainage [Pa/m]: the wall lowered by dH squeezes the
        pore volume by A dH, and the storage beta_f phi (summed over the grid) raises p by
        dH / (H beta_f phi_mean)."""
        grid, s = self.pore.grid, self.pore.state
        return 1.0 / (grid.height * self.pore.config.compressibility * float(np.mean(s.porosity_used)))

    def _push_wall(self, state) -> None:
        """The pore pressure under an impermeable top wall pushes it up (a permeable one has the
        same pressure on both faces). The pressure at the wall is that of the top cells at the
        last fluid step (no flow through the wall: zero gradient there), plus the undrained
        response to the wall's move since then: the fluid is far stiffer than the skeleton, and
        a force taken one step late would drive the wall unstable (negative damping ~ omega^2 dt
        against its own), while this one moves with the wall like a spring, stable below
        2/omega (the wall's dt limit, scene/builder.py)."""
        push_wall(*self._push_arguments(state))

    def _push_arguments(self, state) -> tuple:
        """push_wall's arguments, valid until the next after_step (the grid's height and the top
        cells' pressure change there)."""
        grid, s, walls = self.pore.grid, self.pore.state, state.walls
        area = float(grid.spacing[0] * grid.spacing[1]) * grid.shape[0] * grid.shape[1]
        pressure = float(np.mean(s.pressure[:, :, -1]))
        top, bottom = self.top_wall, float(grid.origin[2])
        return walls.coord, top, bottom, grid.height, pressure, self.wall_stiffness, area, walls.fluid_force

    def wall_stiffness_limit(self, state) -> dict[int, tuple[float, str]]:
        """Stiffness [N/m] the pore fluid adds to a wall it pushes, for the wall's dt limit: the
        undrained A^2 dp/dV at the lowest porosity (the densest sphere packing, or porosity_min if
        higher), with what it is."""
        if not self.pushes_wall:
            return {}
        grid, config = self.pore.grid, self.pore.config
        phi = max(config.porosity_min, DENSEST_POROSITY)
        area = float(grid.spacing[0] * grid.spacing[1]) * grid.shape[0] * grid.shape[1]
        stiffness = area / (grid.height * config.compressibility * phi)
        return {
            self.top_wall: (
                stiffness,
                f"the undrained pore fluid under it (A / (H beta_f phi), beta_f = {config.compressibility:g} "
                f"1/Pa, phi = {phi:g}: {stiffness:.3g} N/m)",
            )
        }

    def _warn_stiffer_wall(self, step: int) -> None:
        """The wall's dt limit counted the fluid's stiffness at the build's height and phi = 0.26
        (wall_stiffness_limit); a lower wall or denser cells make it stiffer: warn once when it
        passes that, since the time step no longer has its margin there."""
        grid = self.pore.grid
        area = float(grid.spacing[0] * grid.spacing[1]) * grid.shape[0] * grid.shape[1]
        if self.warned_stiffer or not self.wall_stiffness * area > self.assumed_wall_stiffness:
            return
        self.warned_stiffer = True
        logging.getLogger("sphere.fluid.darcy").warning(
            "Darcy: at step %d the undrained pore fluid under the top wall is %.3g N/m stiff, more than "
            "the %.3g N/m the time step was chosen for (the wall %.4g m above the grid's bottom, mean "
            "porosity %.3g); a smaller dt or a heavier wall (mass) keeps the wall's margin",
            step, self.wall_stiffness * area, self.assumed_wall_stiffness, grid.height,
            float(np.mean(self.pore.state.porosity_used)),
        )  # fmt: skip

    def initialize(self, state) -> None:
        s = self.pore.state
        if self.top_wall is not None:  # where the wall is now (a stage's approach may have moved it)
            self._fit_grid(state)
        if self.alone:  # open fluid, porosity 1, seen through the clamp as every open cell is
            s.porosity[...] = self.pore.config.porosity_max
        else:
            self._measure(state.particles)
        self.porosity_previous[...] = s.porosity
        s.porosity_rate[...] = 0.0
        self.pore.update_permeability()
        self.pore.update_gradient(state.clock.time)
        if self.pushes_wall:
            self.wall_stiffness = self._undrained_stiffness()

    def grid_step_rehearsal(self) -> tuple:
        arguments = (self.pore.config, self.pore.grid, self.pore.kc, self.fluid_dt, self.top_wall is not None)
        return backward_euler_system, rehearse_grid_step, arguments

    def after_step(self, state) -> None:
        if self.stepped_on_ranks == state.clock.step:
            return  # taken by every MPI rank (step_on_rank), the lead's arrays with it
        self._step(state, state.particles)

    def step_on_rank(self, state, whole, held) -> None:
        """after_step on one MPI rank's part (physics/rank_steps.py): the porosity is sampled on
        slabs (split_grid), each rank its own cells from the particles they can reach, taken
        from every rank's owners in global order (whole.near), so each cell's sum is one rank's;
        the fields are gathered and the pore pressure stepped alike on every rank, bit for bit."""
        p = state.particles
        pos, vel, radius = whole.near(lambda own: self._reached_by(p.pos[own]), p.pos, p.vel, p.radius)
        self._step(state, types.SimpleNamespace(pos=pos, vel=vel, radius=radius))

    def split_grid(self, comm) -> None:
        self.pore.solver.split(comm)
        self.porosity.split(comm, self.pore.solver.slabs)

    def _reached_by(self, pos: np.ndarray) -> np.ndarray:
        """Which ranks' porosity cells can reach each of the particles at pos (whole.near)."""
        return self.porosity.needed_by(pos, 0.5 * self.diameter)

    def rank_copy(self, whole) -> Darcy:
        """Itself: nothing is kept per particle, and every rank steps the whole fluid
        (step_on_rank), which each rank's part then reads."""
        return self

    def _step(self, state, particles) -> None:
        with self.on_its_threads():
            self._grid_step(state, particles)

    def _grid_step(self, state, particles) -> None:
        clock = state.clock
        s = self.pore.state
        grid_speed = self._follow_wall(state) if self.top_wall is not None else 0.0
        if not self.alone:  # without particles the porosity stays as initialize() measured it
            # dphi/dt by backward difference over the fluid step; on a grid that moved, in a
            # frame moving with the grains (rate_in_grains_frame): the rate of the cells moving
            # with the grid, advected with v_p - w, left a source where cells slid past grains at
            # rest; the rate at points fixed in space (from the grains a fluid step back, on the
            # cells now) misses a third of a bed's compaction where the grid moves with it.
            # Under an impermeable wall the cells' own frame: the skeleton's divergence is
            # imposed as the grid's below (and the frame of the grains there spread the pressure
            # of a sealed oedometer, d5-darcy-undrained-skempton, 4 times as much)
            follow_grains = grid_speed and not self.pushes_wall
            if follow_grains:
                largest = 0.5 * self.diameter
                self.porosity.measure_earlier(particles, self.fluid_dt, self.porosity_earlier, largest)
            self._measure(particles)
            np.subtract(s.porosity, self.porosity_previous, out=s.porosity_rate)
            s.porosity_rate *= 1.0 / self.fluid_dt
            if follow_grains:
                np.subtract(s.porosity, self.porosity_earlier, out=self.porosity_earlier)
                self.porosity_earlier *= 1.0 / self.fluid_dt
            if grid_speed:
                rate = (self.porosity_earlier, s.porosity_rate, s.particle_velocity, grid_speed)
                rate_in_grains_frame(*rate, True, not follow_grains)
        # under an impermeable top wall (and floor) the fluid stays in the grid: the grid's change
        # of volume, A dH/dt, is all the pore fluid's (the solid's is conserved), so the
        # skeleton's divergence integrates to it (its mean: dH/dt / H). The lens estimate of the
        # porosity, sampled in a sphere of each cell, holds that only roughly (on a lattice
        # aligned with the grid, to a few per cent at rest and not at all while the cells change
        # faster than the grains follow), and the pore pressure of an undrained bed is that
        # integral: it is imposed. Not under a permeable wall, which the fluid crosses: there
        # the skeleton's divergence integrates to the change of the bed's own volume, which is
        # the grid's only while the bed touches the wall (a wall moving through the water above
        # a bed at rest imposed a compaction of the bed, pore pressures above its buoyant weight)
        mean_source = grid_speed / self.pore.grid.height if self.pushes_wall else None
        try:
            self.pore.advance(self.fluid_dt, clock.time, mean_source)
        except ArithmeticError as exc:
            raise NumericalError(
                f"numerical failure at step {clock.step} (t = {clock.time:.6g} s) in the fluid: {exc}"
            ) from None
        if not self.alone:
            self.porosity_previous[...] = s.porosity
        if self.pushes_wall:
            self.wall_stiffness = self._undrained_stiffness()
            self._warn_stiffer_wall(clock.step)
        # looked at where the count changes (a cell crossing a bound), not every fluid step
        if s.clamped_cells != self.clamped_seen and not (self.warned_below_min and self.logged_above_max):
            self.clamped_seen = s.clamped_cells
            self._warn_clamped(clock.step)

    def _warn_clamped(self, step: int) -> None:
        """Once a run, the first cells whose porosity the equations clamp (the user guide's
        "Porosity clamps"): a warning for cells below porosity_min (grains packed denser than the
        equations take, from overlaps or cells about a grain wide); a line of run.log for cells
        above porosity_max, which are by design (open water, porosity 1, and the sparse cells
        at a bed's surface: their resistance is negligible beside the bed's), or every run with
        water above its bed would warn at its first step."""
        s, config = self.pore.state, self.pore.config
        if not s.clamped_cells:
            return
        log = logging.getLogger("sphere.fluid.darcy")
        dense = int(np.count_nonzero(s.porosity < config.porosity_min))
        if dense and not self.warned_below_min:
            self.warned_below_min = True
            log.warning(
                "Darcy: porosity below fluid.porosity_min = %g in %d of %d fluid cells at step %d (lowest "
                "%.3g), taken as %g: the grains overlap or pack denser than the equations take; the "
                "observable darcy_clamped_cells counts the clamped cells every frame",
                config.porosity_min, dense, self.pore.grid.cell_count, step, float(s.porosity.min()),
                config.porosity_min,
            )  # fmt: skip
        if s.clamped_cells > dense and not self.logged_above_max:
            self.logged_above_max = True
            open_water = int(np.count_nonzero(s.porosity >= 1.0))
            log.info(
                "Darcy: porosity above fluid.porosity_max = %g taken as %g in %d of %d fluid cells at "
                "step %d (%d of them open water)",
                config.porosity_max, config.porosity_max, s.clamped_cells - dense,
                self.pore.grid.cell_count, step, open_water,
            )  # fmt: skip

    def _measure(self, particles) -> None:
        s = self.pore.state
        if self.measured is not None:  # measured on a GPU at the end of this step (gpu_steps)
            s.porosity[...], s.particle_velocity[...] = self.measured
            self.porosity.report_clamped(int(self.measured_clamped[0]))
            return
        # the largest radius of all the particles (a rank may be given only some: step_on_rank)
        largest = 0.5 * self.diameter
        self.porosity.measure(particles, s.porosity, mean_velocity=s.particle_velocity, largest=largest)

    # -- particles -------------------------------------------------------------------------------

    def forces(self, state, spring_dt: float | None = None) -> None:
        if self.pushes_wall:
            self._push_wall(state)
        add_pressure_forces(*self.force_arguments(state))

    def force_arguments(self, state) -> tuple:
        """The arguments of add_pressure_forces, valid until the next after_step (the grid may
        move with the top wall there)."""
        p, grid, s = state.particles, self.pore.grid, self.pore.state
        return (
            p.pos, p.radius, s.gradient, s.porosity_used, self.whole_seepage, grid.origin, grid.spacing,
            self.pore.periodic, self.pore.config.density, self.gravity, p.force,
        )  # fmt: skip

    on_gpu = True

    def gpu_steps(self, state) -> GpuSteps:
        """The force on the particles, and on a wall it pushes (one thread), on a GPU; on a grid
        that keeps its cells (no top wall to follow), also the porosity and the particles' mean
        velocity per cell at the end of each step before a fluid step, so that only the grid's
        fields travel (a moving grid's cells change in this module's step, before the porosity:
        the particles come back for it instead)."""
        from ...kernels.fluid import cuda_darcy

        forces = [(cuda_darcy.pressure_forces, state.particles.count, self.force_arguments(state))]
        if self.pushes_wall:
            forces.insert(0, (cuda_darcy.push_wall, 1, self._push_arguments(state)))
        steps = GpuSteps(forces)
        if self.top_wall is not None:
            return steps
        if self.measured is None:
            s = self.pore.state
            self.measured = (np.zeros_like(s.porosity), np.zeros_like(s.particle_velocity))
        porosity, velocity = self.measured
        measure = self.porosity.gpu_measure(state.particles, porosity, velocity)
        steps.coupling, self.measured_clamped, sort = measure
        steps.coupled = (porosity, velocity, self.measured_clamped)
        steps.scratch = (*sort, porosity, velocity)
        return steps

    own_step_where = GRID_ON_GPU

    def grid_on_gpu(self) -> None:
        from .device_pore_pressure import step_on_gpu

        step_on_gpu(self.pore)

    def grid_device_bytes(self) -> int:
        return self.pore.on.device_bytes() + self.pore.solver.on.device_bytes()

    def particle_arrays(self, state) -> dict:
        """Nothing kept per particle: its force on one is that of the pore pressure where the
        particle is (the fluid's own arrays, kept whole on every MPI rank)."""
        return {}

    # -- restart ---------------------------------------------------------------------------------

    def prognostic_state(self, state) -> dict[str, np.ndarray]:
        s = self.pore.state
        return {
            "pressure": s.pressure,
            "porosity": s.porosity,
            "porosity_previous": self.porosity_previous,
            "gradient": s.gradient,
            "darcy_velocity": s.velocity,  # output only, but made with the last step's faces
            **({"grid_height": np.array(self.pore.grid.height)} if self.top_wall is not None else {}),
        }

    def restore(self, state, arrays: dict) -> None:
        s = self.pore.state
        if self.top_wall is not None:
            self.pore.grid.set_height(float(arrays["grid_height"]))
            self.pore.update_spacing()
        s.pressure[...] = arrays["pressure"]
        s.porosity[...] = arrays["porosity"]
        self.porosity_previous[...] = arrays["porosity_previous"]
        s.gradient[...] = arrays["gradient"]
        self.pore.update_permeability()
        s.velocity[...] = arrays["darcy_velocity"]
        if self.pushes_wall:  # (the walls are restored first: their coordinates are the checkpoint's)
            self.wall_stiffness = self._undrained_stiffness()
            self._push_wall(state)

    # -- diagnostics and output ------------------------------------------------------------------

    def first_unstable(self, state) -> str | None:
        return self.pore.first_bad_cell()

    def output_fields(self, state) -> dict[str, tuple[np.ndarray, str]]:
        s = self.pore.state
        return {
            "pressure": (s.pressure, "Pa"),
            "porosity": (s.porosity, "1"),
            "permeability": (s.permeability, "m2"),
            "darcy_velocity": (s.velocity, "m s-1"),
            **({MOVING_GRID_SPACING: (self.pore.grid.spacing, "m")} if self.top_wall is not None else {}),
        }

    def grid(self) -> FluidGrid:
        return self.pore.grid

    def observables(self, state) -> dict[str, tuple[float, str]]:
        s = self.pore.state
        values = {
            "darcy_mean_pressure": (float(np.mean(s.pressure)), "Pa"),
            "darcy_max_abs_pressure": (float(np.max(np.abs(s.pressure))), "Pa"),
            "darcy_solver_iterations": (float(s.iterations), "1"),
            "darcy_clamped_cells": (float(s.clamped_cells), "1"),
        }
        if self.top_wall is not None:
            grid = self.pore.grid
            values["fluid_grid_height"] = (grid.height, "m")
            values["fluid_pore_volume"] = (float(s.porosity.sum()) * grid.cell_volume, "m3")
        return values

    def summary(self) -> dict[str, str]:
        pore, config = self.pore, self.pore.config
        if pore.kc is None:
            law = f"constant k = {config.permeability.value:g} m^2"
        else:
            law = f"Kozeny-Carman, k_c = {pore.kc:.4g} m^2"
        return {
            "model": "darcy (pore-pressure diffusion, backward Euler)",
            "grid": pore.grid.describe() + pore.on.where,
            "permeability": law,
            "solver": pore.solver.describe(),
            "fluid step": f"{self.fluid_dt:.4g} s (every {self.coupling_steps} DEM steps); explicit limit "
            f"{pore.explicit_limit():.4g} s at the current porosity",
        }
