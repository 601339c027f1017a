"""`[fluid] model = "vans1d"`: a vertical profile of streamwise (x) fluid velocity coupled to the
particles of a laterally periodic cell, for bedload transport (after YADE's HydroForceEngine,
Maurin et al. 2015, 2016, 2018).

Every DEM step the particles feel drag, buoyancy and optional lift from the frozen profile
(kernels/fluid/profile_forces.py). Every coupling interval the particles are averaged over the layers
(kernels/fluid/layer_averaging.py) and the fluid profile is advanced over that same interval with its
own implicit steps (kernels/fluid/vans1d.py), or, for a prescribed flow, left as given.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np

from ...config.consistency import particle_materials
from ...config.fluid_vans1d import LogLawFlow, ProfileFlow, SolvedFlow
from ...kernels.fluid.profile_forces import (
    drag_coefficients,
    profile_forces,
    profile_forces_serial,
    rank_vans1d_steps,
    rank_vans1d_steps_serial,
    vans1d_steps,
    vans1d_steps_serial,
)
from ...kernels.fluid.turbulent_fluctuations import turbulent_fluctuations
from ...kernels.fluid.vans1d import (
    MIXING_KINDS,
    advance_fluid,
    damp_mixing_length,
    mixing_length,
    shear_stress,
)
from ...kernels.serial import use_serial
from ..fluid_plugin import FluidModule, GpuSteps
from .layer_averaging import LayerProfiles, layer_faces
from .poisson import Slabs


class FluidColumn:
    """Velocity profile u at the centres of the layers `faces`, advanced with fixed solid
    profiles (solid, vel_p, exchange); every array is allocated here, once."""

    def __init__(
        self,
        faces: np.ndarray,
        rho: float,
        nu: float,
        mixing: str = "none",
        kappa: float = 0.41,
        packed_solid_fraction: float = 0.61,
        top_no_slip: bool = False,
        lid_velocity: float = 0.0,
        van_driest: float = 0.0,
        sublayer: float = 0.0,
    ):
        """sublayer [m]: no eddy viscosity at the faces below this height above the floor
        (YADE's viscous sublayer); 0 = none."""
        self.faces = np.ascontiguousarray(faces, dtype=np.float64)
        self.centres = 0.5 * (self.faces[1:] + self.faces[:-1])
        n = self.centres.size
        self.rho, self.nu = float(rho), float(nu)
        self.kind = MIXING_KINDS[mixing]
        self.kappa, self.packed_solid_fraction = float(kappa), float(packed_solid_fraction)
        self.top_no_slip = bool(top_no_slip)
        self.lid_velocity = float(lid_velocity)  # of the no-slip lid along x [m/s]
        self.van_driest = float(van_driest)
        self.sublayer_faces = int(np.count_nonzero(self.faces - self.faces[0] < float(sublayer)))
        self.u = np.zeros(n)
        self.mixing = np.zeros(n + 1)  # mixing length at the faces [m]
        self.damped = np.zeros(n + 1)  # the same, damped near the wall (van Driest) [m]
        self.u_star = np.zeros(1)  # friction velocity of the damping [m/s]
        self._coef = np.zeros(n + 1)
        self._work = np.zeros(n)  # the Thomas algorithm's eliminated upper coefficients

    @classmethod
    def regular(cls, bottom, top, cells, stretching=1.0, **kwargs) -> FluidColumn:
        return cls(layer_faces(bottom, top, cells, stretching), **kwargs)

    @property
    def cells(self) -> int:
        return self.centres.size

    def update_mixing_length(self, solid: np.ndarray) -> None:
        mixing_length(self.faces, solid, self.kind, self.kappa, self.packed_solid_fraction, self.mixing)
        self.mixing[: self.sublayer_faces] = 0.0
        damp_mixing_length(self.mixing, self.kappa, self.van_driest, self.u_star[0], self.nu, self.damped)

    def advance(self, solid, vel_p, exchange, source: float, dt: float, steps: int) -> None:
        """`steps` implicit steps of dt [s] with the solid profiles fixed; source = rho g_x - dp/dx
        [N/m^3]. The mixing length must be up to date with solid."""
        advance_fluid(
            self.faces, self.centres, self.u, solid, vel_p, exchange, self.mixing, self.damped, self.kappa,
            self.van_driest, self.u_star, self.rho, self.nu, float(source), self.top_no_slip,
            self.lid_velocity, float(dt), int(steps), self._coef, self._work,
        )  # fmt: skip

    def shear_stress(self, solid: np.ndarray, out: np.ndarray) -> np.ndarray:
        """Fluid shear stress at the n+1 faces [Pa] into `out`."""
        shear_stress(
            self.faces, self.centres, self.u, solid, self.damped, self.rho, self.nu, self.top_no_slip,
            self.lid_velocity, out,
        )  # fmt: skip
        return out


@dataclass
class Vans1dState:
    """state.fluid of a vans1d scene."""

    column: FluidColumn
    profiles: LayerProfiles  # solid profiles of the last coupling
    stress: np.ndarray  # (n+1,) fluid shear stress at the faces [Pa] (diagnostic)
    selected: np.ndarray  # (N,) uint8: 1 = feels the fluid
    counted: np.ndarray  # (N,) uint8: 1 = in the solid profiles the fluid sees (every particle)
    drag_coef: np.ndarray  # (N,) K_p of the last force evaluation [kg/s]
    drag_x: np.ndarray  # (N,) streamwise drag of the last force evaluation [N]


class Vans1d(FluidModule):
    model = "vans1d"
    default_interval = 1.0e-3  # s between fluid updates when [fluid.coupling] gives neither

    def __init__(self, loaded, state):
        super().__init__(loaded, state)
        self.layer_comm = None  # on MPI ranks the grid's communicator (split_grid): layers shared out
        cfg = loaded.case.fluid
        self.cfg = cfg
        box = state.box  # what the fluid requires of the case: config/fluid_vans1d.py case_problems
        p = state.particles
        selected = np.ones(p.count, dtype=np.uint8)
        if cfg.materials:
            names = list(particle_materials(loaded.case))  # material id k is the k-th name
            selected[:] = np.isin(p.material, [names.index(name) for name in cfg.materials])
        if cfg.ids is not None:
            if problem := cfg.ids_problem(p.count):  # particles counted from a placement file
                raise loaded.error(("fluid", "ids"), problem)
            first, last = cfg.ids
            selected[:first] = 0
            selected[last + 1 :] = 0
        selected &= (p.inv_mass > 0).astype(np.uint8)
        flow = cfg.flow
        solved = isinstance(flow, SolvedFlow)
        column = FluidColumn.regular(
            float(box.lower[2]),
            cfg.surface,
            cfg.cells,
            cfg.stretching,
            rho=cfg.density,
            nu=cfg.viscosity,
            mixing=flow.mixing_length if solved else "none",
            kappa=flow.kappa if solved else 0.41,
            packed_solid_fraction=cfg.packed_solid_fraction,
            top_no_slip=solved and flow.top == "no-slip",
            lid_velocity=flow.top_velocity if solved else 0.0,
            van_driest=flow.van_driest if solved else 0.0,
            sublayer=self._sublayer_height(cfg, box) if solved else 0.0,
        )
        self.solved = solved
        self.area = float(box.length[0] * box.length[1])
        self.source = cfg.density * float(box.body_acc[0]) - (flow.pressure_gradient if solved else 0.0)
        self.gravity = np.ascontiguousarray(box.body_acc, dtype=np.float64)
        state.fluid = Vans1dState(
            column=column,
            profiles=LayerProfiles.zeros(cfg.cells),
            stress=np.zeros(cfg.cells + 1),
            selected=selected,
            counted=np.ones(p.count, dtype=np.uint8),
            drag_coef=np.zeros(p.count),
            drag_x=np.zeros(p.count),
        )
        if not solved:
            column.u[:] = prescribed_profile(flow, column.centres)
        self.imposed = None  # the solid fraction of [fluid.solid_fraction] at the layer centres
        if cfg.solid_fraction is not None:
            self.imposed = np.interp(column.centres, cfg.solid_fraction.z, cfg.solid_fraction.value)
            state.fluid.profiles.solid_fraction[:] = self.imposed
        density = p.mass[selected == 1] / (4.0 / 3.0 * np.pi * p.radius[selected == 1] ** 3)
        self.diameter = 2.0 * float(p.radius[selected == 1].mean()) if selected.any() else 0.0
        self.particle_density = float(density.mean()) if density.size else 0.0
        self._dt_limit = self._drag_relaxation_limit(p, selected)
        self._allocate_fluctuations(p.count, cfg.cells)
        self.fluid_steps = 1
        self.substep_dt = 0.0  # the fluid's own implicit steps within a fluid step [s]

    def _allocate_fluctuations(self, count: int, cells: int) -> None:
        """The per-particle state of [fluid.fluctuations] (kernels/fluid/turbulent_fluctuations.py):
        the fluctuation, its remaining lifetime and the number of draws so far, and the Reynolds
        stress they are drawn from; a (1, 3) placeholder without them."""
        spec = self.cfg.fluctuations
        self.fluctuating = spec is not None
        if not self.fluctuating:
            self.fluct = np.zeros((1, 3))
            return
        self.fluct = np.zeros((count, 3))  # [m/s]
        self.fluct_lifetime = np.zeros(count)  # [s] left; <= 0: draw at the next coupling
        self.fluct_draws = np.zeros(count, dtype=np.uint64)
        self.reynolds = np.zeros(cells + 1)  # [Pa] at the layer faces
        self.stream_key = np.arange(count, dtype=np.int64)  # each particle's sequence: its index

    def _fluctuate(self, state, elapsed: float, held=None) -> None:
        """Draw the particles whose fluctuation has lived its time, from the current profile. On
        MPI ranks (`step_on_rank`) the particles `held`, each from the random stream of its
        global index, as one rank draws it."""
        f, spec, col = state.fluid, self.cfg.fluctuations, state.fluid.column
        # the turbulent part of the shear stress alone: the stress with nu = 0
        shear_stress(
            col.faces, col.centres, col.u, f.profiles.solid_fraction, col.damped, col.rho, 0.0,
            col.top_no_slip, col.lid_velocity, self.reynolds,
        )  # fmt: skip
        turbulent_fluctuations(
            state.particles.pos, self.stream_key if held is None else held, f.selected, col.faces,
            self.reynolds, col.rho, col.nu, col.kappa, spec.bed_elevation, np.uint64(spec.seed),
            spec.correlated, elapsed, self.fluct, self.fluct_lifetime, self.fluct_draws,
        )  # fmt: skip

    # ---------------------------------------------------------------- schedule

    @staticmethod
    def _sublayer_height(cfg, box) -> float:
        """z+ nu/u* of fluid.flow.viscous_sublayer [m], u* = sqrt(|S| H/rho) from the driving S
        over the depth H (0 without a sublayer or a driving)."""
        flow = cfg.flow
        driving = cfg.density * float(box.body_acc[0]) - flow.pressure_gradient
        depth = cfg.surface - float(box.lower[2])
        u_star = math.sqrt(abs(driving) * depth / cfg.density)
        if flow.viscous_sublayer == 0.0 or u_star == 0.0:
            return 0.0
        return flow.viscous_sublayer * cfg.viscosity / u_star

    def particle_arrays(self, state) -> dict:
        """Per particle: which feel the fluid and count in its profiles, the drag of the last
        force evaluation (the stability check reads it), and the fluctuations when drawn. The
        profiles themselves are the fluid's own, kept whole on every MPI rank."""
        held = {name: (state.fluid, name) for name in ("selected", "counted", "drag_coef", "drag_x")}
        if self.fluctuating:
            held.update({name: (self, name) for name in ("fluct", "fluct_lifetime", "fluct_draws")})
        return held

    def dt_limit(self) -> tuple[float, str]:
        return min(self._dt_limit, self.coupling_limit(), key=lambda limit: limit[0])

    def _drag_relaxation_limit(self, p, selected) -> tuple[float, str]:
        """The explicit drag needs dt below the relaxation time m/K of every particle; K is at
        least its viscous part 3 pi rho nu d (1 - c)^-n (c the solid fraction), largest at the
        packed solid fraction. (Faster slip raises K further: first_unstable checks m/K of each
        particle as the run goes.)"""
        sel = selected == 1
        if not sel.any():
            return math.inf, ""
        cfg = self.cfg
        hindrance = (1.0 - cfg.packed_solid_fraction) ** (-cfg.drag_exponent)
        k_viscous = 6.0 * math.pi * cfg.density * cfg.viscosity * p.radius[sel] * hindrance
        relax = p.mass[sel] / k_viscous
        i = int(np.argmin(relax))
        return float(relax[i]), (
            f"explicit drag: relaxation time m/K of the particle of radius {p.radius[sel][i]:.4g} m in the "
            f"viscous limit at fluid.packed_solid_fraction = {cfg.packed_solid_fraction:g}"
        )

    def start(self, state) -> None:
        self.start_coupling(state)
        interval = self.fluid_dt
        if self.solved:
            self.fluid_steps = max(1, math.ceil(interval / self.cfg.flow.dt - 1e-9))
            self.substep_dt = interval / self.fluid_steps

    def initialize(self, state) -> None:
        self._average(state)
        self._warn_smooth_floor(state)
        if self.solved and self.cfg.flow.initial == "steady":
            self._steady_start(state)
        if self.fluctuating:
            self._fluctuate(state, 0.0)

    def _warn_smooth_floor(self, state) -> None:
        """A turbulent flow over a clear (smooth) floor with neither sublayer treatment: the
        eddy viscosity reaches the floor, over-mixing the buffer layer (log-law intercept
        B = -1.2 instead of about 5)."""
        flow = self.cfg.flow
        if not self.solved or flow.mixing_length == "none" or flow.van_driest or flow.viscous_sublayer:
            return
        if state.fluid.profiles.solid_fraction[0] > 0.0:
            return  # a bed on the floor: its drag, not a viscous sublayer, holds the flow back
        warnings.warn(
            f'fluid.flow.mixing_length = "{flow.mixing_length}" over a smooth floor (no particle in '
            "the lowest layer) has no viscous-sublayer treatment: the eddy viscosity reaches the "
            "floor; set fluid.flow.van_driest = 26 or fluid.flow.viscous_sublayer = 11.3",
            RuntimeWarning,
            stacklevel=2,
        )

    # ---------------------------------------------------------------- every step

    on_gpu = True
    # the compiled loops with profile_forces in them (forces below; physics/compiled_steps.py)
    force_loops = (vans1d_steps, vans1d_steps_serial, rank_vans1d_steps, rank_vans1d_steps_serial)

    def gpu_steps(self, state) -> GpuSteps:
        from ...kernels.fluid.cuda_profile_forces import profile_forces

        f = state.fluid
        forces = [(profile_forces, state.particles.count, self.force_arguments(state))]
        drag = (f.drag_coef, f.drag_x)  # which its stability test reads
        return GpuSteps(forces, written=drag, checked=drag)

    def forces(self, state, spring_dt=None) -> None:
        kernel = profile_forces_serial if use_serial() else profile_forces
        kernel(*self.force_arguments(state))

    def force_arguments(self, state) -> tuple:
        """The arguments of the one kernel call of `forces`, valid until the next after_step
        (also for the compiled steps)."""
        p, f = state.particles, state.fluid
        col = f.column
        cfg = self.cfg
        return (
            p.pos, p.vel, p.radius, f.selected, col.faces, col.centres, col.u, f.profiles.solid_fraction,
            col.top_no_slip, col.lid_velocity, col.rho, col.nu, cfg.drag_exponent, cfg.packed_solid_fraction,
            self.gravity, cfg.buoyancy == "full", cfg.lift_coefficient, self.fluctuating, self.fluct, p.force,
            f.drag_coef, f.drag_x,
        )  # fmt: skip

    def after_step(self, state) -> None:
        if self.stepped_on_ranks == state.clock.step:
            return  # taken by every MPI rank (step_on_rank), the lead's fluid arrays with it
        self._step(state)

    def step_on_rank(self, state, whole, held) -> None:
        """after_step on one MPI rank's part (physics/rank_steps.py): `held` the global indices of
        its particles, `whole` what it takes of every rank's own particles (EveryRank).
        The drag of each particle held is its own; the profiles, sums over every particle in
        one rank's order, and the column after them are the same on every rank, bit for bit;
        so is each particle's fluctuation, drawn where it is held from its own random stream."""
        self._step(state, whole, held)

    def _step(self, state, whole=None, held=None) -> None:
        self._average(state, whole)
        if self.solved:
            f = state.fluid
            prof = f.profiles
            f.column.advance(
                prof.solid_fraction, prof.vel, prof.exchange_coefficient, self.source, self.substep_dt,
                self.fluid_steps,
            )  # fmt: skip
            if self.fluctuating:
                self._fluctuate(state, self.fluid_dt, held)

    def _average(self, state, whole=None) -> None:
        """Solid profiles of the current particles, the drag evaluated with the current fluid.
        Every particle is in them, as in YADE's HydroForceEngine: a fixed rough bed or particles
        of materials that do not feel the fluid hold its solid fraction and take its drag (at their
        own velocity, zero when fixed), though only the selected mobile ones receive forces. On
        MPI ranks (split_grid) the layers are shared out, each rank about as many particles'
        centres, and each rank averages its layers from every rank's own particles that reach
        them, in global order (whole.near), as one rank sums them; the profiles are gathered."""
        p, f = state.particles, state.fluid
        col, cfg = f.column, self.cfg
        drag_coefficients(
            p.pos, p.vel, p.radius, f.counted, col.faces, col.centres, col.u, f.profiles.solid_fraction,
            col.top_no_slip, col.lid_velocity, col.rho, col.nu, cfg.drag_exponent, cfg.packed_solid_fraction,
            f.drag_coef, f.drag_x,
        )  # fmt: skip
        summed = (p.pos, p.vel, p.radius, f.counted, f.drag_coef, f.drag_x)
        layers = None
        if whole is not None:  # (split_grid has given the ranks' communicator)
            layers = self._layers(state, whole.own())
            summed = whole.near(lambda own: self._reaching(state, own, layers.bounds), *summed)
        f.profiles.average(*summed, col.faces, self.area, layers)
        if self.imposed is not None:
            f.profiles.solid_fraction[:] = self.imposed
        col.update_mixing_length(f.profiles.solid_fraction)

    def split_grid(self, comm) -> None:
        self.layer_comm = comm

    def _layers(self, state, own: np.ndarray) -> Slabs:
        """Collective: this rank's share of the layers, as Slabs of (n, 1, 1) planes: the bounds
        that give each rank about as many of the counted particles' centres (counted over every
        rank's own particles)."""
        faces = state.fluid.column.faces
        n = faces.size - 1
        counted = own[state.fluid.counted[own] == 1]
        centre = _layers_of(faces, state.particles.pos[counted, 2])
        counts = self.layer_comm.allreduce(np.bincount(centre, minlength=n).astype(np.int64))
        below = np.concatenate(([0], np.cumsum(counts)))
        size = self.layer_comm.Get_size()
        inner = np.searchsorted(below, np.arange(1, size) * (below[-1] / size), side="left")
        bounds = np.concatenate(([0], np.minimum(inner, n), [n])).astype(np.int64)
        return Slabs((n, 1, 1), self.layer_comm, bounds)

    @staticmethod
    def _reaching(state, own: np.ndarray, bounds: np.ndarray) -> np.ndarray:
        """(ranks, n) bool: which ranks' layers each of the particles own (local indices) reaches
        (layer_of its lowest and highest points, as the average takes them); none for a particle
        not counted."""
        faces = state.fluid.column.faces
        z, r = state.particles.pos[own, 2], state.particles.radius[own]
        lowest, highest = _layers_of(faces, z - r), _layers_of(faces, z + r)
        marks = (lowest[None, :] < bounds[1:, None]) & (highest[None, :] >= bounds[:-1, None])
        return marks & (state.fluid.counted[own] == 1)[None, :]

    def _steady_start(self, state, tol: float = 1e-9, max_rounds: int = 20000) -> None:
        """Advance the fluid over the fixed initial particles until its profile stops changing:
        implicit steps 100 x fluid.flow.dt long, in rounds of 100, until a round changes u by less
        than tol relative to its largest value."""
        f = state.fluid
        col = f.column
        dt = 100.0 * self.cfg.flow.dt
        for rounds in range(1, max_rounds + 1):
            before = col.u.copy()
            prof = f.profiles
            try:
                col.advance(prof.solid_fraction, prof.vel, prof.exchange_coefficient, self.source, dt, 100)
                self._average(state)
                change = float(np.abs(col.u - before).max())
            except ZeroDivisionError:  # the profile went to inf and nan: a pivot of its solve was 0
                change = math.nan
            if not math.isfinite(change):
                raise self.loaded.error(
                    ("fluid", "flow", "initial"),
                    "the fluid profile over the initial particles went non-finite after "
                    f"{rounds * 100 * dt:g} s of fluid time: check the driving (domain.gravity) and the "
                    "fluid's parameters",
                )
            if change <= tol * max(float(np.abs(col.u).max()), 1e-30):
                return
        raise self.loaded.error(
            ("fluid", "flow", "initial"),
            f"no steady fluid profile over the initial particles after {max_rounds * 100 * dt:g} s of "
            'fluid time; start from initial = "rest"',
        )

    # ---------------------------------------------------------------- restart

    def prognostic_state(self, state) -> dict:
        f = state.fluid
        prof = f.profiles
        return {
            "u": f.column.u,
            "u_star": f.column.u_star,
            "solid_fraction": prof.solid_fraction,
            "vel": prof.vel,
            "exchange_coefficient": prof.exchange_coefficient,
            "drag": prof.drag,
            **(
                {
                    "fluctuation": self.fluct,
                    "fluctuation_lifetime": self.fluct_lifetime,
                    "fluctuation_draws": self.fluct_draws,
                }
                if self.fluctuating
                else {}
            ),
        }

    def restore(self, state, arrays) -> None:
        f = state.fluid
        f.column.u[...] = arrays["u"]
        f.column.u_star[...] = arrays["u_star"]
        for name in ("solid_fraction", "vel", "exchange_coefficient", "drag"):
            getattr(f.profiles, name)[...] = arrays[name]
        if self.fluctuating:
            self.fluct[...] = arrays["fluctuation"]
            self.fluct_lifetime[...] = arrays["fluctuation_lifetime"]
            self.fluct_draws[...] = arrays["fluctuation_draws"]
        f.column.update_mixing_length(f.profiles.solid_fraction)

    # ---------------------------------------------------------------- diagnostics

    def first_unstable(self, state) -> str | None:
        f = state.fluid
        u = f.column.u
        bad = np.flatnonzero(~np.isfinite(u))
        if bad.size:
            k = int(bad[0])
            return (
                f"the vans1d fluid velocity is {u[k]} m/s in layer {k} (z = {f.column.centres[k]:.6g} m); "
                "a smaller fluid.flow.dt or fluid.coupling.interval may help"
            )
        p = state.particles
        ratio = f.drag_coef * p.inv_mass * state.clock.dt
        i = int(np.argmax(ratio)) if ratio.size else 0
        if ratio.size and ratio[i] > 1.0:
            relax = 1.0 / (f.drag_coef[i] * p.inv_mass[i])
            return (
                f"particle {i}: its drag relaxation time m/K = {relax:.3g} s "
                f"is below dt = {state.clock.dt:.3g} s, so the explicit drag is unstable; use a smaller dt"
            )
        return None

    def bed_shear_stress(self, state) -> float:
        f = state.fluid
        return float(f.column.shear_stress(f.profiles.solid_fraction, f.stress).max())

    def observables(self, state) -> dict:
        p, f = state.particles, state.fluid
        tau = self.bed_shear_stress(state)
        if p.count == 0:  # clear water: no sediment to measure
            return {"bed_shear_stress": (tau, "Pa")}
        g = float(np.linalg.norm(self.gravity))
        rho = self.cfg.density
        sel = f.selected == 1
        volume = 4.0 / 3.0 * np.pi * p.radius[sel] ** 3
        flux = float(np.sum(volume * p.vel[sel, 0])) / self.area
        d = self.diameter
        scale = math.sqrt(max(self.particle_density / rho - 1.0, 0.0) * g * d**3)
        shields = tau / ((self.particle_density - rho) * g * d) if self.particle_density > rho else math.nan
        return {
            "bed_shear_stress": (tau, "Pa"),
            "shields_number": (shields, "1"),
            "sediment_flux": (flux, "m2 s-1"),
            "q_star": (flux / scale if scale > 0 else math.nan, "1"),
        }

    def output_fields(self, state) -> dict:
        f = state.fluid
        prof = f.profiles
        fluid = {"layer_height": (f.column.centres, "m"), "fluid_velocity": (f.column.u, "m s-1")}
        if state.particles.count == 0:  # no particles: the solid fraction, if imposed, alone
            if self.imposed is not None:
                fluid["solid_fraction"] = (prof.solid_fraction, "1")
            return fluid
        return {
            **fluid,
            "solid_fraction": (prof.solid_fraction, "1"),
            "particle_velocity": (prof.vel, "m s-1"),
            "drag": (prof.drag, "N m-3"),
        }

    def summary(self) -> dict:
        cfg = self.cfg
        flow = cfg.flow
        mesh = "regular" if cfg.stretching == 1.0 else f"stretched x{cfg.stretching:g}"
        if self.solved:
            how = f"solved, mixing length {flow.mixing_length}, top {flow.top}, "
            how += f"fluid dt {self.substep_dt:.3g} s"
        else:
            how = f"prescribed ({flow.kind})"
        return {
            "model": "vans1d (1D vertical profile, laterally periodic cell)",
            "layers": f"{cfg.cells} ({mesh}) up to z = {cfg.surface:g} m",
            "flow": how,
            "coupling": f"every {self.coupling_steps} DEM steps",
        }


def prescribed_profile(flow, z: np.ndarray) -> np.ndarray:
    """u at heights z of a log-law or tabulated flow [m/s]."""
    if isinstance(flow, LogLawFlow):
        height = np.maximum(z - flow.bed_level, flow.roughness_length)
        return flow.friction_velocity / flow.kappa * np.log(height / flow.roughness_length)
    if isinstance(flow, ProfileFlow):
        return np.interp(z, flow.z, flow.u)
    raise TypeError(f"not a prescribed flow: {flow!r}")


def _layers_of(faces: np.ndarray, z: np.ndarray) -> np.ndarray:
    """The layer of each height z [m], as kernels/fluid/layer_averaging.py layer_of takes it
    (faces[k] <= z < faces[k+1], clipped to 0 .. n-1)."""
    return np.clip(np.searchsorted(faces, z, side="right") - 1, 0, faces.size - 2)
