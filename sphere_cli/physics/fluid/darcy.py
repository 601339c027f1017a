"""Darcy pore-pressure flow coupled to the particles (`[fluid] model = "darcy"`).

The fluid is the pore-pressure equation of physics/fluid/pore_pressure.py on the shared fluid grid.
Each fluid step (every fluid.coupling.steps DEM steps, after the kick and the clock) measures the
porosity and the mean particle velocity per cell from the particles (physics/fluid/porosity.py),
takes dphi/dt as the backward difference over the fluid step, and solves one implicit step.
The forces hook of every DEM step adds to each particle the pressure-gradient force -V grad p
and the buoyancy -rho_f V g (kernels/fluid/darcy.py).
"""

from __future__ import annotations

import logging
import math

import numpy as np

from ...config.fluid_darcy import DarcyFluid
from ...errors import NumericalError
from ...kernels.fluid.darcy import add_pressure_forces
from ..fluid_plugin import FluidModule
from .grid import FluidGrid, fluid_grid
from .pore_pressure import PorePressure, fixed_pressure_cells
from .porosity import Porosity

# porosity of the densest packing of equal spheres, 1 - pi / (3 sqrt 2) (FCC): the lowest a bed
# of spheres reaches, where the permeability and so the coupling's time limit are smallest
DENSEST_POROSITY = 0.26
# fraction of the drag relaxation time rho_s k / mu a fluid step may take (stable at 0.3 and
# unstable at 0.5 in the settling-bed test)
COUPLING_FRACTION = 0.2


class Darcy(FluidModule):
    """The Darcy fluid of a scene (physics/fluid_plugin.py has the hooks and where they run)."""

    model = "darcy"

    def __init__(self, loaded, state):
        super().__init__(loaded, state)
        config: DarcyFluid = loaded.case.fluid
        box, particles = state.box, state.particles
        if box.periodic[2]:
            raise loaded.error(
                ("domain", "periodic"),
                "the Darcy model needs a bounded z axis (its top and bottom boundaries); make z non-periodic",
            )
        if config.grid.follow_top_wall:
            raise loaded.error(
                ("fluid", "grid", "follow_top_wall"),
                'true is available for model = "navier-stokes" only; the Darcy grid spans the box',
            )
        grid = fluid_grid(config.grid, box, particles.radius, loaded)
        _, _, empty = fixed_pressure_cells(config, grid)
        if empty:
            raise loaded.error(
                ("fluid", "fixed_pressure", empty[0]),
                f"holds no cell centre of the fluid grid ({grid.describe()}); widen the region",
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
        self.porosity = Porosity(grid, particles.count)
        self.porosity_previous = np.zeros(grid.shape)  # phi at the last fluid step [-]
        self.gravity = np.asarray(box.body_acc, dtype=np.float64)
        self.warned_clamp = False
        state.fluid = self.pore.state

    # -- schedule --------------------------------------------------------------------------------

    def fluid_step_limit(self) -> tuple[float, str]:
        """The diffusion is implicit and sets no limit; the coupling is explicit. A compacting
        skeleton raises, through the source term, a pressure whose gradient pushes back on the
        grains one fluid step later, like a Darcy drag of relaxation time rho_s k / mu. Measured
        on a settling bed (tests/physics/test_darcy_coupled.py): stable with a fluid step of
        0.3 rho_s k / mu, blowing up at 0.5; the limit is COUPLING_FRACTION of it, with k at
        the densest sphere packing (phi = 0.26, or porosity_min if higher; the constant k
        otherwise) and rho_s the lightest density of the particles that move (fixed ones are
        pushed but do not answer)."""
        if self.alone:
            return (
                math.inf,
                "no particles to couple to, and the implicit pore-pressure step is stable at any step",
            )
        if math.isinf(self.lightest_density):
            return math.inf, "no particle moves: the pore pressure pushes on nothing that answers"
        config = self.pore.config
        phi = max(config.porosity_min, DENSEST_POROSITY)
        if self.pore.kc is None:
            k = config.permeability.value
        else:
            k = self.pore.kc * phi**3 / (1.0 - phi) ** 2
        relaxation = self.lightest_density * k / config.viscosity
        limit = COUPLING_FRACTION * relaxation
        where = "" if self.pore.kc is None else f" at porosity {phi:g}"
        return limit, (
            f"explicit Darcy coupling: {COUPLING_FRACTION:g} rho_s k / mu with rho_s = "
            f"{self.lightest_density:.4g} kg/m^3, k = {k:.3g} m^2{where}, mu = {config.viscosity:g} Pa s"
        )

    def initialize(self, state) -> None:
        s = self.pore.state
        if self.alone:  # open fluid, porosity 1, seen through the clamp as every open cell is
            s.porosity[...] = self.pore.config.porosity_max
        else:
            self._measure(state)
        self.porosity_previous[...] = s.porosity
        s.porosity_rate[...] = 0.0
        self.pore.update_permeability()
        self.pore.update_gradient(state.clock.time)

    def after_step(self, state) -> None:
        clock = state.clock
        s = self.pore.state
        if not self.alone:  # without particles the porosity stays as initialize() measured it
            self._measure(state)
            np.subtract(s.porosity, self.porosity_previous, out=s.porosity_rate)
            s.porosity_rate *= 1.0 / self.fluid_dt
        try:
            self.pore.advance(self.fluid_dt, clock.time)
        except ArithmeticError as exc:
            raise NumericalError(
                f"numerical failure at step {clock.step} (t = {clock.time:.6g} s) in the fluid: {exc}"
            ) from None
        if not self.alone:
            self.porosity_previous[...] = s.porosity
        if s.clamped_cells and not self.warned_clamp:
            self.warned_clamp = True
            config = self.pore.config
            logging.getLogger("sphere.fluid.darcy").warning(
                "Darcy: porosity clamped to [%g, %g] (fluid.porosity_min, fluid.porosity_max) in %d of %d "
                "fluid cells at step %d; the observable darcy_clamped_cells counts them every frame",
                config.porosity_min, config.porosity_max, s.clamped_cells, self.pore.grid.cell_count,
                clock.step,
            )  # fmt: skip

    def _measure(self, state) -> None:
        s = self.pore.state
        self.porosity.measure(state.particles, s.porosity, mean_velocity=s.particle_velocity)

    # -- particles -------------------------------------------------------------------------------

    def forces(self, state, spring_dt: float | None = None) -> None:
        p, grid, s = state.particles, self.pore.grid, self.pore.state
        add_pressure_forces(
            p.pos, p.radius, s.gradient, grid.origin, grid.spacing, self.pore.periodic,
            self.pore.config.density, self.gravity, p.force,
        )  # fmt: skip

    # -- restart ---------------------------------------------------------------------------------

    def prognostic_state(self, state) -> dict[str, np.ndarray]:
        s = self.pore.state
        return {
            "pressure": s.pressure,
            "porosity": s.porosity,
            "porosity_previous": self.porosity_previous,
            "gradient": s.gradient,
            "darcy_velocity": s.velocity,  # output only, but made with the last step's faces
        }

    def restore(self, state, arrays: dict) -> None:
        s = self.pore.state
        s.pressure[...] = arrays["pressure"]
        s.porosity[...] = arrays["porosity"]
        self.porosity_previous[...] = arrays["porosity_previous"]
        s.gradient[...] = arrays["gradient"]
        self.pore.update_permeability()
        s.velocity[...] = arrays["darcy_velocity"]

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
        }

    def grid(self) -> FluidGrid:
        return self.pore.grid

    def observables(self, state) -> dict[str, tuple[float, str]]:
        s = self.pore.state
        return {
            "darcy_mean_pressure": (float(np.mean(s.pressure)), "Pa"),
            "darcy_max_abs_pressure": (float(np.max(np.abs(s.pressure))), "Pa"),
            "darcy_solver_iterations": (float(s.iterations), "1"),
            "darcy_clamped_cells": (float(s.clamped_cells), "1"),
        }

    def summary(self) -> dict[str, str]:
        pore, config = self.pore, self.pore.config
        if pore.kc is None:
            law = f"constant k = {config.permeability.value:g} m^2"
        else:
            law = f"Kozeny-Carman, k_c = {pore.kc:.4g} m^2"
        return {
            "model": "darcy (pore-pressure diffusion, backward Euler)",
            "grid": pore.grid.describe(),
            "permeability": law,
            "solver": pore.solver.describe(),
            "fluid step": f"{self.fluid_dt:.4g} s (every {self.coupling_steps} DEM steps); explicit limit "
            f"{pore.explicit_limit():.4g} s at the current porosity",
        }
