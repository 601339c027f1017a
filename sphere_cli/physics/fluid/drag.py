"""Fluid-particle interaction of the Navier-Stokes model: drag and pressure-gradient force on each
particle, the particles' semi-implicit velocity update, and the equal and opposite force density
on the fluid (laws and scheme in kernels/fluid/drag.py).

Called by the fluid module (physics/fluid/navier_stokes.py) in its hooks, with its fluid state `fs`
(cell-centred fs.v (nx,ny,nz,3) [m/s], fs.porosity (nx,ny,nz) [-], fs.grad_p (nx,ny,nz,3) [Pa/m] of the
last fluid step; fs.f_i (nx,ny,nz,3) [N/m^3], fs.k_drag (nx,ny,nz) [kg/(m^3 s)] written here):
- forces():        every DEM step, after contacts and walls: adds -V grad(p) and the drag to each
                   particle's force;
- kick():          replaces Motion.kick: the second half kick, exact for the drag relaxation;
- fluid_forcing(): before each fluid step, after the kick: f_i, the force density of the fluid on
                   the particles of each cell that the fluid step takes (the drag they will
                   receive over the next interval, settled against what they received over the
                   last one), and k_drag = its derivative with respect to the fluid velocity, so
                   the fluid momentum update takes the drag implicitly as -(f_i + k_drag (v_new -
                   v)) (fs.f_exchange).
Formulation A (pressure in both phases: fluid momentum -phi grad p - f_i) exchanges the drag
alone, its -phi grad p already holding the reaction of the pressure-gradient force; formulation
B (pressure in the fluid only: -grad p - f_i) exchanges drag and pressure-gradient force.
"""

from __future__ import annotations

import itertools
import math
import warnings

import numpy as np

from ...config.drag import DragConfig
from ...kernels.fluid.drag import (
    DI_FELICE,
    GIDASPOW,
    cell_coefficients,
    cell_shares,
    drag_kick,
    drag_kick_serial,
    drag_rate,
    exchange,
    merged_rows,
    particle_drag,
    particle_drag_serial,
)
from ...kernels.neighbors import counting_sort
from ...kernels.serial import use_serial
from ...state import State
from ..fluid_plugin import GpuSteps
from .poisson import Slabs
from .porosity import bin_in_cells
from .self_induced import MODES, lattice_modes

LAWS = {"gidaspow": GIDASPOW, "di-felice": DI_FELICE}


class FluidParticleDrag:
    # the arrays kept per particle (and `disturbance` where `corrected`)
    PER_PARTICLE = ("cell_of", "wrapped", "coef", "f_other", "f_drag", "impulse")

    def __init__(
        self,
        config: DragConfig,
        density: float,
        viscosity: float,
        grid,
        n_particles: int,
        pressure_in_fluid_only: bool,
    ):
        """density [kg/m^3], viscosity [Pa s] of the fluid; grid: the FluidGrid (origin (3,) [m]
        lower corner, spacing (3,) [m], shape (nx, ny, nz), periodic (3,)); pressure_in_fluid_only:
        formulation B."""
        self.config = config
        self.law = LAWS[config.law]
        self.density = float(density)
        self.viscosity = float(viscosity)
        self.floor = float(config.porosity_floor)
        self.pressure_force = bool(config.pressure_force)
        self.pressure_exchanged = self.pressure_force and pressure_in_fluid_only
        self.origin = np.asarray(grid.origin, dtype=np.float64)
        self.spacing = np.asarray(grid.spacing, dtype=np.float64)
        self.shape = tuple(int(n) for n in grid.shape)
        self.cells = np.asarray(self.shape, dtype=np.int64)
        self.periodic = np.asarray(grid.periodic, dtype=np.uint8)
        cells = self.shape[0] * self.shape[1] * self.shape[2]
        n = n_particles
        self.cell_of = np.zeros(n, dtype=np.int64)  # cell of each particle centre (flat index)
        self.wrapped = np.zeros((n, 3))  # centres wrapped into the periodic box (scratch) [m]
        self.coef = np.zeros(n)  # K [kg/s]
        self.f_other = np.zeros((n, 3))  # every force but the drag [N]
        self.f_drag = np.zeros((n, 3))  # drag for the next first half kick [N]
        self.impulse = np.zeros((n, 3))  # drag impulse since the last fluid step [N s]
        self.predicted = np.zeros((cells, 3))  # drag expected over that interval [N/m^3]
        self.solid = np.zeros(cells)  # volume of the particles centred in each cell [m^3]
        # the cell-averaged drag's per-cell means, measured with the porosity at each fluid step
        # (empty with the per-particle drag): (1 - phi) V_cell / solid, diameter [m], velocity [m/s]
        self.averaged = config.averaging == "cell"
        self.cell_share = np.zeros(cells if self.averaged else 0)
        self.cell_diameter = np.zeros(cells if self.averaged else 0)
        self.cell_velocity = np.zeros((cells if self.averaged else 0, 3))
        # the bands of each particle's self-induced velocity u' [m/s] (physics/fluid/
        # self_induced.py), empty when it is kept; the grid's band weights [1/m] and rates [1/m^2]
        # per component, for the spacing they were computed for
        self.corrected = config.self_induced == "subtract" and not self.averaged
        self.disturbance = np.zeros((n if self.corrected else 0, 3, MODES))
        self.band_weight = np.zeros((3, MODES))
        self.band_rate = np.zeros((3, MODES))
        self.band_decay = np.zeros((3, MODES))  # exp(-nu rate dt) for this dt
        self.cell_coef = np.zeros(cells if self.corrected else 0)  # sum of K per cell [kg/s]
        self.response_spacing = np.zeros(3)
        self.case_spacing = self.spacing.copy()  # the grid's cells as the case gives them [m]
        self.seen_spacing = np.zeros(3)  # the spacing at the last step [m]
        self.decay_dt = 0.0
        self.start = np.zeros(cells + 1, dtype=np.int64)
        self.order = np.zeros(n, dtype=np.int64)
        self.every_cell = Slabs(self.shape)  # the cells one rank settles (fluid_forcing)
        self.warned = False
        self.found_below = np.zeros(1, dtype=np.int64)  # by the compiled steps (loop_arguments)
        self.below = None  # on a GPU: (1,) the particle-steps under the porosity floor (gpu_steps)
        self.exchanged_on_device = False  # a GPU takes the momentum exchange (gpu_steps)
        # on MPI ranks: what it takes of every rank's particles (physics/rank_steps.py
        # EveryRank); None on one rank, which holds them all
        self.whole = None
        # on MPI ranks with the self-induced velocity subtracted (plan_exchange): the (list
        # builds, spacing) the plan is for, and the plan: (own particles, table, merge,
        # merged cells, merged coefficients) of kernels/fluid/drag.py rank_cell_coefficients,
        # the rows sent to and received from each rank, and their boxes (Python's, compiled)
        self.plan_for = None
        # a grid following the top wall stretches its cells along z at every fluid step: its plan
        # is made by columns of cells (x and y, which keep their cells), once a list build
        self.stretches = False
        self.plan = None
        self.plan_rows = None
        self.plan_boxes = None
        self.plan_mail = None

    @property
    def inv_cell_volume(self) -> float:
        """1 / the volume of the grid's current cells [1/m^3] (they change when the grid follows
        the top wall: self.spacing is the grid's own array)."""
        return 1.0 / float(np.prod(self.spacing))

    def forces(self, state: State, fs, spring_dt: float | None = None) -> None:
        """Add the fluid forces to state.particles.force (spring_dt = 0: the initial state's). On
        one thread the kernels' serial twins (kernels/serial.py), as in the compiled steps."""
        serial = use_serial()
        bin_in_cells(*self._binning(state))
        drag = particle_drag_serial if serial else particle_drag
        below = drag(*self._drag_arguments(state, fs, spring_dt == 0.0))
        if below:
            self._warn_below(state.clock.step, fs.porosity.reshape(-1), f"{below} particle(s) this step")

    def _binning(self, state: State) -> tuple:
        """The arguments of bin_particles: each particle's fluid cell into cell_of."""
        return (
            state.particles.pos, self.origin, self.spacing, self.cells, self.periodic, self.cell_of,
            self.wrapped,
        )  # fmt: skip

    def _drag_arguments(self, state: State, fs, initial: bool) -> tuple:
        """The arguments of particle_drag (`initial`: the forces of the initial state)."""
        p = state.particles
        return (
            self.law, self.density, self.viscosity, self.floor, self.pressure_force, self.cell_of, p.vel,
            p.radius, p.inv_mass, fs.v.reshape(-1, 3), fs.porosity.reshape(-1), fs.grad_p.reshape(-1, 3),
            state.clock.dt, initial, self.cell_share, self.cell_diameter, self.cell_velocity,
            self.disturbance, p.force, self.f_other, self.coef, self.f_drag,
        )  # fmt: skip

    def loop_arguments(self, state: State, fs) -> tuple:
        """The drag's argument of the compiled steps (kernels/fluid/drag.py drag_steps, and
        rank_drag_steps on an MPI rank, whose sums of the cells' drag coefficients are
        rank_cell_coefficients's), valid until the next fluid step (and on a rank the next list
        build): the grid's response bands follow its cells here, as the kick would make them
        (they change only at fluid steps)."""
        coefficients = None
        if self.corrected:
            self._follow_grid(state.clock.dt)
            coefficients = (self.cell_of, self.coef, self.cell_coef)
            if self.whole is not None:
                if self.plan_mail is None:
                    self.plan_mail = self.whole.mail(*self.plan_rows, width=2)
                coefficients = (*coefficients, *self.plan, self.plan_mail)
        self.found_below[0] = 0
        drag = self._drag_arguments(state, fs, False)
        return self._binning(state), drag, coefficients, self.found_below, not self.warned

    def steps_taken(self, state: State, fs, done: int) -> None:
        """After `done` compiled steps: warn of the particles the last of them found under the
        porosity floor, at that step, as `forces` would have."""
        if self.found_below[0] and not self.warned:
            since = f"{self.found_below[0]} particle(s) this step"
            self._warn_below(state.clock.step + done - 1, fs.porosity.reshape(-1), since)

    def _warn_below(self, step: int, phi, how_many: str) -> None:
        """Warn, once a run, that particles' cells are below the porosity floor at `step`."""
        if self.warned:
            return
        self.warned = True
        below = np.flatnonzero(phi[self.cell_of] < self.floor)  # none where they have moved on since
        where = "the porosity of particles' fluid cells"
        if below.size:
            cell = int(self.cell_of[below[0]])
            index = tuple(int(k) for k in np.unravel_index(cell, self.shape))
            where = f"porosity {phi[cell]:.3g} in fluid cell {index}"
        warnings.warn(
            f"step {step}: {where} is below fluid.drag.porosity_floor = "
            f"{self.floor}; the drag uses the floor there ({how_many}, not repeated)",
            RuntimeWarning,
            stacklevel=3,
        )

    def report_below(self, state: State, fs) -> None:
        """At a fluid step, before the porosity changes: warn of the particles a GPU found under
        the porosity floor since the last one (gpu_steps)."""
        if self.below is not None and self.below[0]:
            since = f"{self.below[0]} particle-step(s) since the last fluid step"
            self._warn_below(state.clock.step, fs.porosity.reshape(-1), since)
            self.below[0] = 0

    def gpu_steps(self, state: State, fs, fluid_dt: float | None = None) -> GpuSteps:
        """`forces` and `kick` on a GPU (kernels/fluid/cuda_drag.py), with the arrays as they are
        now; the grid's response bands follow its cells here, at the fluid's steps, which alone
        change them. The particles under the porosity floor are counted on the device, and
        reported at the next fluid step (report_below). With fluid_dt [s] (a grid that keeps its
        cells), also the momentum exchange of fluid_forcing at the end of each step before a fluid
        step, as `coupling`: the drag's arrays then stay on the device."""
        from ...kernels.fluid import cuda_drag as k
        from ...kernels.fluid import cuda_porosity as sort

        p, n, dt = state.particles, state.particles.count, state.clock.dt
        cells = self.start.size - 1
        if self.below is None:  # the device's counters and its sort of particles by cell
            self.below = np.zeros(1, dtype=np.int64)
            self.gpu_sort = tuple(np.zeros(size, np.int32) for size in (cells, cells + 1, cells, n))
        count, start, following, order = self.gpu_sort
        u, grad_p = fs.v.reshape(-1, 3), fs.grad_p.reshape(-1, 3)
        forces = (
            p.pos, self.origin, self.spacing, self.cells, self.periodic, self.wrapped, self.law, self.density,
            self.viscosity, self.floor, self.pressure_force, self.cell_of, p.vel, p.radius, p.inv_mass, u,
            fs.porosity.reshape(-1), grad_p, dt, self.cell_share, self.cell_diameter, self.cell_velocity,
            self.disturbance, p.force, self.f_other, self.coef, self.f_drag, self.below,
        )  # fmt: skip
        by_cell = [
            (sort.count_in_cells, n, (self.cell_of, count)),
            (sort.cell_starts, cells, (count, start, following)),
            (sort.fill_cells, n, (self.cell_of, following, order)),
        ]
        kick = []
        if self.corrected:
            self._follow_grid(dt)
            kick = [*by_cell, (k.cell_coefficients, cells, (start, order, self.coef, count, self.cell_coef))]
        kick.append((k.drag_kick, n, self.kick_arguments(state, fs)))
        per_particle = (self.cell_of, self.coef, self.f_other, self.f_drag, self.impulse, self.disturbance)
        steps = GpuSteps([(k.drag_forces, n, forces)], kick, (*per_particle, self.below))
        steps.scratch = (*self.gpu_sort, self.wrapped, self.cell_coef)
        self.exchanged_on_device = fluid_dt is not None
        if self.exchanged_on_device:
            exchange = (
                start, order, self.impulse, self.coef, p.inv_mass, self.f_other, p.vel, p.radius, u, grad_p,
                self.pressure_exchanged, fluid_dt, self.inv_cell_volume, self.disturbance,
                fs.f_i.reshape(-1, 3), fs.k_drag.reshape(-1), fs.f_exchange.reshape(-1, 3), self.predicted,
                self.solid,
            )  # fmt: skip
            sorted_by_cell = (sort.sort_cells, cells, (start, order, count))
            steps.coupling = [*by_cell, sorted_by_cell, (k.exchange, cells, exchange)]
            steps.coupled = (fs.f_i, fs.k_drag, self.solid, self.below)  # which the fluid's step reads
            steps.written += (self.predicted, self.cell_velocity, self.cell_diameter)
        return steps

    def kick(self, state: State, fs) -> None:
        """Second half kick of the particles with the drag of the last forces() call; then each
        particle's self-induced velocity follows the drag of the step."""
        if self.corrected:
            self._follow_grid(state.clock.dt)
            self._cell_coefficients(state)
        (drag_kick_serial if use_serial() else drag_kick)(*self.kick_arguments(state, fs))

    def kick_arguments(self, state: State, fs) -> tuple:
        """The arguments of drag_kick (kernels/fluid/drag.py)."""
        p = state.particles
        return (
            p.vel, p.angvel, p.torque, p.inv_mass, p.inv_inertia, self.cell_of, fs.v.reshape(-1, 3),
            self.coef, self.f_other, state.clock.dt, p.force, self.f_drag, self.impulse, self.disturbance,
            self.cell_coef, 1.0 / self.inv_cell_volume, self.band_weight, self.band_rate, self.band_decay,
            self.viscosity, self.viscosity / self.density,
        )  # fmt: skip

    def _cell_coefficients(self, state: State) -> None:
        """cell_coef, the sum of the drag coefficients of each cell's particles in particle
        order. On an MPI rank (self.whole), of the cells its particles can visit until the next
        list build (the others are left unread), from every rank's own particles that can be in
        them, in global order (plan_exchange): as one rank sums them, with the messages of the
        compiled loop (kernels/fluid/drag.py rank_cell_coefficients)."""
        if self.whole is None:
            cell_coefficients(self.cell_of, self.coef, self.cell_coef)
            return
        self.plan_exchange(state)
        own, table, merge, merged_cell, merged_coef = self.plan
        table[own, 0] = self.cell_of[own]
        table[own, 1] = self.coef[own]
        self.whole.swap([table], *self.plan_rows, self.plan_boxes)
        merged_rows(table, merge, merged_cell, merged_coef)
        cell_coefficients(merged_cell, merged_coef, self.cell_coef)

    def plan_exchange(self, state: State) -> None:
        """Collective, on an MPI rank with the self-induced velocity subtracted, once a list
        build: which of this rank's own particles each other rank takes for its cells' sums of
        the drag coefficients (those that can be in a cell the other's particles can visit
        until the next build: _reachable_cells), and the global order in which this rank sums
        its own and those it receives (kernels/fluid/drag.py rank_cell_coefficients). On a grid
        that stretches (`stretches`: it follows the top wall) the cells move along z at each
        fluid step, so cells are taken by whole columns, which keep theirs: a rank takes
        another's particles that can be in the columns its own can visit, at any height (a
        superset of those in its cells, whatever the stretch), and the plan holds until the
        next build."""
        spacing = self.spacing[:2] if self.stretches else self.spacing
        key = (state.neighbors.builds, *spacing)
        if self.whole is None or not self.corrected or self.plan_for == key:
            return
        whole = self.whole
        reachable = self._reachable_cells(state)  # (points, n)
        places = self.start.size - 1  # the cells, or their columns
        if self.stretches:
            reachable //= self.shape[2]  # the cells' columns: (i, j) of the C-ordered (i, j, k)
            places = self.shape[0] * self.shape[1]
        visited = np.zeros(places, dtype=bool)
        visited[reachable.reshape(-1)] = True
        every = whole.every_mask(visited)  # (ranks, cells or columns), packed bits
        own = whole.own()
        gid = whole.gid()
        cells = reachable[:, own]  # (points, own)
        ranks = every.shape[0]
        # the ranks whose particles can visit a cell this rank's own can be in (its neighbours),
        # each sent those of its own that can be in one of that rank's cells
        near = np.flatnonzero(self._marked(every, np.unique(cells)).any(axis=1))
        send = {}
        for r in near[near != whole.rank]:
            send[int(r)] = own[self._marked(every[r], cells).any(axis=0)]
        arrived = whole.alltoall([gid[send[r]] if r in send else None for r in range(ranks)])
        receive, first = {}, gid.size  # received rows follow the held particles' in the table
        for r, gids in enumerate(arrived):
            if gids is not None:
                receive[r] = np.arange(first, first + gids.size)
                first += gids.size
        rows = np.concatenate([own, *receive.values()]).astype(np.int64)
        order = np.concatenate([gid[own], *(g for g in arrived if g is not None)])
        merge = rows[np.argsort(order, kind="stable")]
        merged = (np.empty(merge.size, dtype=np.int64), np.empty(merge.size))
        self.plan = (own, np.zeros((first, 2)), merge, *merged)
        self.plan_rows = (send, receive)
        self.plan_boxes = whole.boxes(send, receive, 2)
        self.plan_mail = None  # the compiled loop's, made by loop_arguments
        self.plan_for = key

    @staticmethod
    def _marked(packed: np.ndarray, index: np.ndarray) -> np.ndarray:
        """The entries `index` of masks packed by np.packbits along their last axis (EveryRank.
        every_mask; big-endian: entry i is bit 7 - i % 8 of byte i // 8), as bool (...,
        index.shape)."""
        return ((packed[..., index >> 3] >> (7 - (index & 7)).astype(np.uint8)) & 1).astype(bool)

    def _reachable_cells(self, state: State) -> np.ndarray:
        """(points, n) int64: cells each particle this rank holds can be in until the next list
        build: each moves at most half the skin from where it was at the last
        (NeighborSearch's threshold), so the cells of the points of a lattice over the box of
        that half width around it, at most a cell apart along each axis, hold it. On a grid that
        stretches, the points of the particle's own height only (plan_exchange takes their
        columns)."""
        reach = 0.5 * state.neighbors.skin
        ref = state.neighbors.ref_pos
        points = [np.linspace(-reach, reach, int(np.ceil(2.0 * reach / h)) + 1) for h in self.spacing]
        if self.stretches:  # the columns alone are wanted: the points of one height
            points[2] = np.zeros(1)
        offsets = list(itertools.product(*points))
        cells = np.empty((len(offsets), ref.shape[0]), dtype=np.int64)
        shifted = np.empty_like(ref)
        for row, offset in zip(cells, offsets, strict=True):
            bin_in_cells(ref + offset, self.origin, self.spacing, self.cells, self.periodic, row, shifted)
        return cells

    def _follow_grid(self, dt: float) -> None:
        """The grid's response bands for its cells now and their decay over dt [s]. The cells
        change when the grid follows the top wall: the bands are those of the spacing rounded to
        a step of 1 % (in its logarithm) from the case's own, a function of the spacing alone, so
        that a resumed run takes the same bands as the run it continues. Nothing is computed
        while the spacing and dt stay as they were (every step of a fixed grid)."""
        seen = self.seen_spacing
        spacing = self.spacing
        moved = spacing[0] != seen[0] or spacing[1] != seen[1] or spacing[2] != seen[2]
        if moved:
            seen[:] = spacing
            steps = np.round(np.log(spacing / self.case_spacing) * 100.0)
            rounded = self.case_spacing * np.exp(steps / 100.0)
            if np.any(rounded != self.response_spacing):
                self.band_weight[:], self.band_rate[:] = lattice_modes(rounded)
                self.response_spacing[:] = rounded
            else:
                moved = False
        if moved or dt != self.decay_dt:
            np.exp(self.band_rate * (-self.viscosity / self.density * dt), out=self.band_decay)
            self.decay_dt = dt

    def fluid_forcing(self, state: State, fs, fluid_dt: float, slabs: Slabs | None = None) -> None:
        """Fill fs.f_i and fs.k_drag for a fluid step of fluid_dt [s] (also the time since the
        last call): the drag expected over the next interval at the fluid velocity now, settled
        against the impulses received since the last call (kernels/fluid/drag.py, "Momentum
        exchange"); the impulses restart from zero. A GPU that took the exchange on the device
        (gpu_steps) has filled them already. On MPI ranks (slabs split: physics/fluid/poisson.py)
        each rank settles the cells of its slab from the particles in them, and the cells'
        arrays are gathered."""
        if not self.exchanged_on_device:
            self._exchange(state, fs, fluid_dt, slabs if slabs is not None else self.every_cell)
        if self.averaged:
            self._share(fs.porosity.reshape(-1))

    def _exchange(self, state: State, fs, fluid_dt: float, slabs: Slabs) -> None:
        p = state.particles
        n = p.count  # (a rank of a split run passes those in its slab's cells and others)
        cell_of, order = self.cell_of[:n], self.order[:n]
        counting_sort(cell_of, self.start.size - 1, self.start, order)
        plane = self.shape[1] * self.shape[2]
        exchange(
            slabs.lo * plane, slabs.hi * plane, self.start, order, self.impulse, self.coef, p.inv_mass,
            self.f_other, p.vel, p.radius, fs.v.reshape(-1, 3), fs.grad_p.reshape(-1, 3),
            self.pressure_exchanged, fluid_dt, self.inv_cell_volume, self.disturbance,
            fs.f_i.reshape(-1, 3), fs.k_drag.reshape(-1), fs.f_exchange.reshape(-1, 3), self.predicted,
            self.solid,
        )  # fmt: skip
        if slabs.split:
            nx = self.shape[0]
            for field in (fs.f_i, fs.k_drag, self.predicted.reshape(nx, -1), self.solid.reshape(nx, -1)):
                slabs.gather(field)

    def measure_cell_means(self, state: State, porosity, phi, largest: float | None = None) -> None:
        """The cell-averaged drag's means (the porosity estimate's lens-weighted mean diameter and
        velocity of each cell) with phi, the porosity of each cell; at a fluid step, before
        fluid_forcing (which then takes the particles' volume per cell and the shares). largest:
        the scene's largest radius [m] (Porosity.measure)."""
        porosity.measure(
            state.particles,
            phi,
            self.cell_velocity.reshape(*self.shape, 3),
            self.cell_diameter.reshape(self.shape),
            largest,
        )

    def start_cell_means(self, state: State, phi) -> None:
        """The volume of the particles centred in each cell, and the shares, before the first
        fluid step (fluid_forcing keeps them afterwards)."""
        p = state.particles
        bin_in_cells(p.pos, self.origin, self.spacing, self.cells, self.periodic, self.cell_of, self.wrapped)
        volume = math.pi / 6.0 * (2.0 * p.radius) ** 3
        self.solid[:] = np.bincount(self.cell_of, weights=volume, minlength=self.solid.size)
        self._share(phi.reshape(-1))

    def _share(self, phi) -> None:
        """cell_share = (1 - phi) V_cell / solid (0 where no particle is centred)."""
        cell_shares(phi, self.solid, self.inv_cell_volume, self.cell_share)

    def fluid_force(self, state: State, fs) -> np.ndarray:
        """Total force of the fluid on all particles (drag and pressure-gradient force) [N]."""
        total = self.f_drag.sum(axis=0)
        if self.pressure_force:
            volume = math.pi / 6.0 * (2.0 * state.particles.radius) ** 3
            total = total - volume @ fs.grad_p.reshape(-1, 3)[self.cell_of]
        return total

    def prognostic_state(self) -> dict[str, np.ndarray]:
        """What a bitwise restart needs: the drag of the next first half kick, the impulses not
        yet handed to the fluid and the drag the fluid took ahead for them."""
        arrays = {"force": self.f_drag, "impulse": self.impulse, "predicted": self.predicted}
        if self.corrected:
            arrays["self_induced"] = self.disturbance
        if self.averaged:
            arrays.update(share=self.cell_share, diameter=self.cell_diameter, velocity=self.cell_velocity)
        return arrays

    def restore(self, arrays: dict) -> None:
        self.f_drag[...] = arrays["force"]
        self.impulse[...] = arrays["impulse"]
        self.predicted[...] = arrays["predicted"]
        if self.corrected:
            self.disturbance[...] = arrays["self_induced"]
        if self.averaged:
            self.cell_share[...] = arrays["share"]
            self.cell_diameter[...] = arrays["diameter"]
            self.cell_velocity[...] = arrays["velocity"]

    def settling_speed(self, diameter: float, excess_density: float, gravity: float, porosity=1.0) -> float:
        """Terminal speed [m/s] in fluid at rest of a sphere of `diameter` [m] whose density
        differs from the fluid's by `excess_density` [kg/m^3], under `gravity` [m/s^2], in a cell
        of `porosity` (1: clear fluid): the root of V k(v) v = V excess_density g, by bisection
        (the drag grows with v; the laws' slow-flow drag is at least 0.96 of Stokes', and more
        below porosity 1, so the root lies below twice Stokes' speed)."""
        weight = abs(excess_density) * gravity  # per particle volume [N/m^3]
        if weight == 0.0 or diameter <= 0.0:
            return 0.0
        low, high = 0.0, 2.0 * weight * diameter**2 / (18.0 * self.viscosity)
        for _ in range(200):
            speed = 0.5 * (low + high)
            k = drag_rate(self.law, porosity, diameter, speed, self.density, self.viscosity, self.floor)
            low, high = (speed, high) if k * speed < weight else (low, speed)
        return 0.5 * (low + high)

    @staticmethod
    def dt_limit() -> tuple[float, str]:
        """The drag puts no limit on dt: exact relaxation on the particles, implicit in the fluid."""
        return math.inf, "none from the drag (exponential on the particles, implicit in the fluid)"
