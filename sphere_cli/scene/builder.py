"""Case -> scene: radii, positions, walls, the physics modules in play, and the time step.

Only what the case asks for is allocated: no walls, no wall arrays; a dry case, no fluid (the
fluid model's module is not even imported); a fluid-only case (no particles), no particle
motion, neighbour search or contacts: the fluid's own step is all its step does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .. import compile_ahead, ranks
from ..config.consistency import MANY_STEPS, box_problems, step_problem
from ..config.load import LoadedCase, warn
from ..config.memory import memory_problems
from ..config.schema import LAW_KEYS, Case, FilePlacement, LatticePlacement, RandomPlacement
from ..errors import CaseError, ResumeRefused
from ..kernels.neighbors import worst_overlap
from ..physics.compiled_steps import CompiledSteps
from ..physics.contact import PairContactForces, load_overlaps, one_contact_limit, stability_limit
from ..physics.fluid_plugin import FluidModule, build_fluid
from ..physics.materials import ContactTables, assign_materials, contact_tables
from ..physics.module import Step, order_problems
from ..physics.motion import Motion
from ..physics.neighbors import NeighborSearch, allocate_neighbor_list
from ..physics.observe.energy_budget import EnergyBudget
from ..physics.observe.observables import Observer
from ..physics.stages import Stages
from ..physics.walls import PlaneWallForces, WallMotion, WallScales, apply_modes
from ..state import Box, Clock, Particles, State
from .groups import apply_groups
from .packing import (
    lattice_positions,
    particle_file_path,
    random_positions,
    read_particle_file,
    worst_overlap_of,
)
from .radii import draw_radii
from .walls import allocate_walls, rough_layers

# dt = "auto" set by a fluid limit this many times below that of the particles alone is more
# likely a wrong unit (a viscosity in cP, say) than the physics meant: warned of
FLUID_LIMIT_RATIO = 1e3
# dt = "auto" never takes more than this share of the stability bound
AUTO_SHARE = 0.9


@dataclass
class Scene:
    case: Case
    state: State
    motion: Motion | None  # None (and neighbors, contact) in a scene without particles
    neighbors: NeighborSearch | None
    contact: PairContactForces | None
    walls: PlaneWallForces | None
    dt_limit: float  # smallest stability limit of one contact alone or a fluid process [s]
    dt_limit_reason: str = ""  # what sets it
    dt_bound: float = math.inf  # stability bound with many contacts at a sphere (physics/contact.py) [s]
    dt_bound_reason: str = ""
    fluid: FluidModule | None = None
    wall_motion: WallMotion | None = None  # only if some wall moves in some stage
    stages: Stages | None = None  # only if the case has [[stages]]
    budget: EnergyBudget | None = None  # only when the energy budget is observed
    observer: Observer | None = None
    # every module in play, in the order their hooks run (physics/module.py), and their bound
    # hooks: set by order_modules(), again whenever a module or a hook method is replaced
    modules: tuple = ()
    step: Step = field(default_factory=lambda: Step(()))

    # modules whose state a checkpoint may hold or lack (a resume starts them afresh)
    OPTIONAL_STATE = ("energy_budget", "observables")

    @property
    def tables(self) -> ContactTables:
        return self.contact.tables

    @property
    def finished(self) -> bool:
        """True once the last stage has ended (never without stages)."""
        return self.stages is not None and self.stages.finished

    def order_modules(self) -> None:
        """The scene's modules in the order of the step (physics/module.py ORDER) and their hooks."""
        every = (
            self.wall_motion, self.motion, self.neighbors, self.budget, self.contact, self.walls,
            self.fluid, self.stages, self.observer,
        )  # fmt: skip
        self.modules = tuple(m for m in every if m is not None)
        problems = order_problems(self.modules)
        if problems:  # a programming error: the order above breaks physics/module.py ORDER
            raise RuntimeError("; ".join(problems))
        if self.step.compiled is not None:  # steps it took and has not brought back
            self.step.compiled.to_host(self.state)
        self.step = Step(self.modules, particles=self.state.particles.count > 0)
        world = ranks.current()
        if world is not None:
            from ..physics.rank_steps import RankSteps

            self.step.compiled = RankSteps.of(self, world)
        elif self.case.simulation.device == "cuda":
            from ..physics.device_steps import DeviceSteps  # the CPU path imports no CUDA package

            self.step.compiled = DeviceSteps.of(self)
        else:
            self.step.compiled = CompiledSteps.of(self.step)

    def compute_initial_forces(self) -> None:
        """Forces of the initial state, for the first half kick: no time has passed, so the
        tangential springs do not grow."""
        for forces in self.step.forces:
            forces(self.state, spring_dt=0.0)


# Extreme values (a density of 1e-308 kg/m^3, a stiffness of 1e308 N/m) overflow masses and limits
# to 0 or inf; the dt they give is refused by name (_resolve_dt), so numpy's warnings would only
# print source lines to the user before that message.
@np.errstate(all="ignore")
def build_scene(loaded: LoadedCase, restart=None) -> Scene:
    """Build the scene of a case; with `restart` (a CheckpointData), the particles come from the
    checkpoint (placement files are not needed again) and every module's state is restored."""
    case = loaded.case
    if not case.has_particles:
        return _build_fluid_only(loaded, restart)
    made = _bodies(loaded, restart)
    state, walls_state, scales, fluid = made.state, made.walls_state, made.scales, made.fluid
    contact = PairContactForces(made.tables)
    walls = PlaneWallForces(contact) if walls_state is not None else None
    wall_motion = WallMotion() if walls_state is not None and _walls_move(case) else None
    stages = None
    if case.stages:
        stages = Stages(case, walls_state, scales, contact)
    elif walls_state is not None:
        apply_modes(walls_state, dict(enumerate(case.walls)), scales, state.box, 0.0, walls_state.coord)
    neighbors = NeighborSearch(state, made.tables.frictional)
    scene = Scene(
        case=case,
        state=state,
        motion=Motion(),
        neighbors=neighbors,
        contact=contact,
        walls=walls,
        dt_limit=made.dt_limit[0],
        dt_limit_reason=made.dt_limit[1],
        dt_bound=made.dt_bound[0],
        dt_bound_reason=made.dt_bound[1],
        fluid=fluid,
        wall_motion=wall_motion,
        stages=stages,
    )
    if fluid is not None:
        fluid.start(state)
    observed = case.output.observables
    scene.observer = Observer(scene, observed)
    if "energy_budget" in observed.quantities:
        scene.budget = EnergyBudget(scene)
    scene.order_modules()
    if restart is None:
        helper = compile_ahead.start(scene)
        try:
            if stages is not None:
                stages.begin(state, 0)
            neighbors.rebuild(state)
            _check_overlaps(loaded, state)
            if fluid is not None:
                fluid.initialize(state)
        except BaseException:
            compile_ahead.stop(helper)  # a refused packing, an interrupt: nothing to wait for
            raise
        compile_ahead.finish(helper)
        scene.compute_initial_forces()
        if scene.budget is not None:
            scene.budget.start()
    else:
        _restore(loaded, scene, restart)
    return scene


@dataclass
class _Bodies:
    """What the time step depends on: the particles, walls and fluid of a case, before any
    kernel runs (so `sphere validate` can take the same dt as `run`, check_build)."""

    state: State  # its clock's dt resolved
    tables: ContactTables
    walls_state: object  # scene/walls.py WallState, None without walls
    scales: WallScales | None
    fluid: FluidModule | None
    dt_limit: tuple[float, str]  # (smallest limit of one contact alone or a fluid process [s], what sets it)
    dt_bound: tuple[float, str]  # (stability bound with many contacts at a sphere [s], what sets it)


def _bodies(loaded: LoadedCase, restart=None, files: dict | None = None) -> _Bodies:
    """The particles (placed and grouped, or from `restart`), walls and fluid of a case with
    particles, and its time step; `files` as check_build's."""
    case = loaded.case
    rng = np.random.default_rng(case.particles.seed)
    tables = contact_tables(case)
    n_placed = None
    if restart is None:
        pos, radius, vel, angvel, placement_file = _initial_particles(loaded, rng, files)
        material = _file_materials(loaded, tables, placement_file)
        if material is None:
            material = assign_materials(tables.fractions, radius.size, rng)
        n_placed = radius.size
        rough_pos, rough_radius, rough_wall = rough_layers(case, case.domain.lower, case.domain.upper)
        if rough_radius.size:
            pos = np.concatenate([pos, rough_pos])
            radius = np.concatenate([radius, rough_radius])
            vel = np.concatenate([vel, np.zeros_like(rough_pos)])
            angvel = np.concatenate([angvel, np.zeros_like(rough_pos)])
            material = np.concatenate([material, np.zeros(rough_radius.size, dtype=np.int32)])
    else:
        saved = restart.arrays["particles"]
        pos, radius, vel, angvel = saved["pos"], saved["radius"], saved["vel"], saved["angvel"]
        material = np.zeros(radius.size, dtype=np.int32)  # restored with the particles
        if "material" in saved:
            material[:] = saved["material"]
    n = radius.size
    density = np.array([m.density for m in tables.materials])[material]
    mass = density * 4.0 / 3.0 * np.pi * radius**3
    inertia = 0.4 * mass * radius**2
    if restart is None:
        _check_masses(loaded, tables, material, radius, mass, inertia, placement_file)
    particles = Particles(
        pos=pos,
        vel=vel,
        angvel=angvel,
        force=np.zeros((n, 3)),
        torque=np.zeros((n, 3)),
        radius=radius,
        mass=mass,
        inertia=inertia,
        inv_mass=1.0 / mass,
        inv_inertia=1.0 / inertia,
        material=material,
        vel_pred=vel.copy(),
        angvel_pred=angvel.copy(),
    )
    box = _box(case)
    if restart is not None:
        # which particles are free decides the walls' default masses (and so dt): take it now
        particles.inv_mass[:] = restart.arrays["particles"]["inv_mass"]
    if restart is None:
        _check_inside(loaded, box, pos[:n_placed], radius[:n_placed])
        placed = slice(0, n_placed)
        apply_groups(
            case,
            pos[placed],
            vel[placed],
            angvel[placed],
            particles.inv_mass[placed],
            particles.inv_inertia[placed],
            *_file_groups(loaded, placement_file),
        )
        particles.inv_mass[n_placed:] = 0.0
        particles.inv_inertia[n_placed:] = 0.0
        particles.vel_pred[:] = vel

    walls_state = None
    scales = None
    if case.walls:
        walls_state = allocate_walls(
            case.walls, n, box.lower, box.upper, tables.wall_table, _walls_move(case), tables.frictional
        )
        if restart is None and n > n_placed:
            walls_state.attached = np.arange(n_placed, n, dtype=np.int64)
            walls_state.attached_wall = rough_wall
        scales = WallScales(case, tables, radius, mass, particles.inv_mass)
    skin = case.simulation.neighbor_skin * float(radius.max())
    state = State(
        clock=Clock(dt=math.nan),  # set below, once every module has stated its limit
        box=box,
        particles=particles,
        neighbors=allocate_neighbor_list(n, skin),
        walls=walls_state,
    )
    fluid = build_fluid(loaded, state)
    # the limit of one contact alone (a given dt above it is refused; dt = "auto" takes dt_safety
    # of it) and the stability bound for spheres held by many contacts (dt = "auto" stays below
    # it; a given dt above it is warned of), each lowered by the driven walls and the fluid
    faces = [w.face for w in case.walls]
    contacts = (tables, radius, mass, material, case.particles.overlap_tolerance, faces)
    limits = [one_contact_limit(*contacts), stability_limit(*contacts)]
    speed = np.sqrt(np.einsum("ij,ij->i", vel, vel))
    _warn_soft_contacts(loaded, contacts, speed, getattr(case.fluid, "density", 0.0))
    if walls_state is not None:
        pushed = fluid.wall_stiffness_limit(state) if fluid is not None else {}
        limits = [_driven_wall_limit(case, walls_state, scales, box, *limit, pushed) for limit in limits]
    solid_limit = limits[0][0]
    if fluid is not None:
        fluid_limit = fluid.dt_limit()
        limits = [min(limit, fluid_limit, key=lambda item: item[0]) for limit in limits]
    (dt_limit, dt_reason), bound = limits
    # not a stability limit (no safety share of it is taken), the most a step may be
    motion = _moving_wall_limit(case, float(radius.min()) if n else math.inf)
    state.clock.dt = _resolve_dt(loaded, dt_limit, dt_reason, solid_limit, bound, motion)
    if state.clock.dt == motion[0]:
        dt_limit, dt_reason = motion  # what the run reports as setting its step
    return _Bodies(state, tables, walls_state, scales, fluid, (dt_limit, dt_reason), bound)


# below this radius [m] (well below an atom's) an unusable mass is the radius's fault, above it
# the density's (_check_masses)
TINIEST_RADIUS = 1e-20


def _check_masses(
    loaded: LoadedCase, tables: ContactTables, material, radius, mass, inertia, placement_file
) -> None:
    """Refuse particles whose mass or moment of inertia float64 cannot hold with its inverse
    (a radius of 1e-120 m: r^3 and m r^2 underflow to 0, and the steps would divide by them),
    naming the key that sets the radii."""
    held = (mass > 0.0) & (inertia > 0.0) & np.isfinite(1.0 / mass) & np.isfinite(1.0 / inertia)
    if held.all():
        return
    i = int(np.argmin(held))
    density = tables.materials[material[i]].density
    if radius[i] > TINIEST_RADIUS:  # a radius of any size a grain can have: the density is at fault
        key = _material_key(loaded.case, tables.names[material[i]], "density", ("particles", "density"))
        what = "densities this small"
    else:
        from_file = placement_file is not None and placement_file.radius is not None
        key = ("particles", "placement", "path") if from_file else ("particles", "radius")
        what = "radii this small (give them in metres)"
    raise loaded.error(
        key,
        f"particle {i} (r = {radius[i]:.4g} m, density {density:.4g} kg/m^3) has a mass of "
        f"{mass[i]:.4g} kg and a moment of inertia of {inertia[i]:.4g} kg m^2, whose inverses "
        f"overflow float64: {what} cannot be simulated",
    )


def _material_key(case: Case, name: str, key: str, otherwise: tuple) -> tuple:
    """The location of `key` in the [[materials]] entry called `name` where that entry sets it,
    else `otherwise` (the single-material form's key, or [contact]'s default)."""
    for k, entry in enumerate(case.materials):
        if entry.name == name and getattr(entry, key) is not None:
            return ("materials", k, key)
    return otherwise


def _warn_soft_contacts(loaded: LoadedCase, contacts: tuple, speed, fluid_density: float) -> None:
    """Warn, naming the stiffness key, of each material whose particles would overlap their
    stiffest support too deeply under their weight (a tenth of a radius) or in a head-on impact
    at their initial speed (a quarter: physics/contact.py load_overlaps): the run may go on, but
    spheres that deep in one another are not what the contact law describes, and pass through
    walls."""
    tables, radius, mass, material, _, faces = contacts
    case = loaded.case
    gravity = math.hypot(*case.domain.gravity)
    key = LAW_KEYS[case.contact.model][0]
    for a, what in load_overlaps(tables, radius, mass, speed, material, faces, gravity, fluid_density):
        loc = _material_key(case, tables.names[a], key, ("contact", key))
        warn(
            loaded.describe(
                loc,
                f"{what}: contacts this soft for the load let spheres pass through one "
                "another and through walls: stiffen the contact",
            )
        )


def _walls_move(case: Case) -> bool:
    """Whether some wall of the case moves in some stage."""
    return any(w.moves for w in case.walls) or any(w.moves for s in case.stages for w in s.walls)


def _box(case: Case) -> Box:
    """The domain box of the case: its corners [m], periodic axes and body acceleration [m/s^2]."""
    dom = case.domain
    return Box(
        lower=np.array(dom.lower, dtype=np.float64),
        upper=np.array(dom.upper, dtype=np.float64),
        periodic=np.array(dom.periodic, dtype=np.uint8),
        body_acc=np.array(dom.gravity, dtype=np.float64),
    )


def _build_fluid_only(loaded: LoadedCase, restart=None) -> Scene:
    """The scene of a case without particles: the fluid alone. No particle arrays but empty
    ones (the fluid reads them), no motion, neighbour search or contacts, and dt from the
    fluid's limits (_fluid_only_dt)."""
    case = loaded.case
    state, fluid, (limit, reason) = _fluid_alone(loaded)
    scene = Scene(
        case=case,
        state=state,
        motion=None,
        neighbors=None,
        contact=None,
        walls=None,
        dt_limit=limit,
        dt_limit_reason=reason,
        dt_bound=limit,
        dt_bound_reason=reason,
        fluid=fluid,
    )
    fluid.start(state)
    scene.observer = Observer(scene, case.output.observables)
    scene.order_modules()
    if restart is None:
        fluid.initialize(state)
    else:
        _restore(loaded, scene, restart)
    return scene


def _fluid_alone(loaded: LoadedCase) -> tuple[State, FluidModule, tuple[float, str]]:
    """The state (no particles, its clock's dt resolved) and fluid of a case without particles,
    and the fluid's limit on dt with what sets it."""
    none3, none = np.zeros((0, 3)), np.zeros(0)
    particles = Particles(
        pos=none3, vel=none3, angvel=none3, force=none3, torque=none3, radius=none, mass=none,
        inertia=none, inv_mass=none, inv_inertia=none, material=np.zeros(0, dtype=np.int32),
        vel_pred=none3, angvel_pred=none3,
    )  # fmt: skip
    state = State(clock=Clock(dt=math.nan), box=_box(loaded.case), particles=particles, neighbors=None)
    fluid = build_fluid(loaded, state)
    limit, reason = fluid.dt_limit()
    state.clock.dt = _fluid_only_dt(loaded, fluid, limit, reason)
    return state, fluid, (limit, reason)


@np.errstate(all="ignore")  # as build_scene
def check_build(loaded: LoadedCase, files: dict | None = None) -> None:
    """What `sphere validate` checks of the build: the particles, walls and fluid built as `run`
    builds them, before any kernel runs; the dt of the case resolved from their limits (a given
    dt above them, or one giving too many steps, refused as `run` refuses it); the fluid's
    coupling to it (its interval against its limit, its boundary modulations against its step);
    the particles' overlaps; and the fluid's initial fields read (read_inputs). So a batch job
    validated before it is queued does not fail at its start for its input: a lattice that
    cannot hold the particles, a random insertion that cannot place them, a placement file
    unreadable, with unknown columns or values, particles outside the box, materials or groups
    the case does not name, a fluid's grid or rules against its radii and count.
    `files`: the placement files read so far, by path, for a caller checking many cases that
    share one (sphere sweep's members: a file of 10^6 particles takes seconds to read), read
    into and not changed here."""
    if loaded.case.has_particles:
        made = _bodies(loaded, files=files)
        state, fluid = made.state, made.fluid
        p, box = state.particles, state.box
        _refuse_overlap(loaded, *worst_overlap_of(p.pos, p.radius, box.lower, box.upper, box.periodic))
        if loaded.case.simulation.device == "cuda":  # what the GPU cannot run, wherever validate runs
            from ..physics.device_steps import search_grid_problem

            problem = search_grid_problem(NeighborSearch(state, made.tables.frictional), p.count)
            if problem is not None:
                raise CaseError(problem)
    else:
        state, fluid, _ = _fluid_alone(loaded)
    if fluid is not None:
        fluid.start(state)
        fluid.read_inputs()


def _fluid_only_dt(loaded: LoadedCase, fluid: FluidModule, limit: float, reason: str) -> float:
    """dt of a scene without particles, given the fluid's limit on it and what sets it [s]:
    with dt = "auto", the coupling interval where it sets the limit (one step a fluid step:
    there are no particles to sub-step), else AUTO_SHARE of the limit; a limit of none (an
    implicit fluid step with nothing to couple to) is refused, asking for dt."""
    sim = loaded.case.simulation
    if sim.dt != "auto":
        if sim.dt > limit:
            raise loaded.error(
                ("simulation", "dt"),
                f'above the stability limit {limit:.4g} s ({reason}); use dt <= {limit:.4g} s or dt = "auto"',
            )
        _check_steps(loaded, sim.dt)
        return float(sim.dt)
    if not math.isfinite(limit):
        raise loaded.error(
            ("simulation", "dt"),
            f'"auto" takes the fluid\'s limits when there are no particles, and this fluid has none '
            f"({reason}); give dt in seconds (or fluid.coupling.interval)",
        )
    interval = fluid.coupling_interval()
    if interval is not None and limit == interval:
        dt, how = limit, f"{reason}, one step a fluid step"
    else:
        dt, how = AUTO_SHARE * limit, f"{AUTO_SHARE:g} x {reason}"
    if dt > sim.duration:  # a single step longer than the run would overshoot its end
        dt, how = float(sim.duration), "simulation.duration, below the fluid's limit"
    _check_steps(loaded, dt, f'"auto" gives {dt:.3g} s ({how}): ')
    steps = sim.duration / dt
    if steps > MANY_STEPS:
        warn(
            loaded.describe(
                ("simulation", "dt"),
                f"gives {dt:.3g} s ({how}): {steps:.3g} steps to reach t = {sim.duration:g} s",
            )
        )
    return dt


def _driven_wall_limit(
    case: Case, walls, scales: WallScales, box: Box, limit: float, reason: str, pushed: dict
):
    """The smaller of `limit` and the stability limit of every stress-driven wall mode of the
    case (against one layer of contacts, physics/walls.py, and the fluid where `pushed`, wall
    index -> (stiffness [N/m], what), says a fluid pushes it), with what sets it."""
    from ..kernels.walls import wall_areas

    area = np.zeros(len(walls.faces))
    wall_areas(walls.axis, walls.sign, walls.coord, box.lower, box.upper, area)
    index = {w.face: k for k, w in enumerate(case.walls)}
    for spec, where in _wall_specs(case):
        if not spec.driven:
            continue
        k = index[spec.face]
        fluid, fluid_reason = pushed.get(k, (0.0, ""))
        value = scales.dt_limit(spec, k, float(area[k]), fluid)
        if value < limit:
            limit = value
            also = f" and {fluid_reason}" if fluid else ""
            reason = (
                f"stress-driven {spec.face} wall ({where}): mass {scales.mass(spec, float(area[k])):.4g} kg "
                f"against one layer of contacts{also}, 2/omega (its damping is implicit)"
            )
    return limit, reason


def _wall_specs(case: Case) -> list[tuple]:
    """(spec, its key: walls[k] or stages[i].walls[k]) of every wall of the case and its stages."""
    specs = [(w, f"walls[{k}]") for k, w in enumerate(case.walls)]
    return specs + [
        (w, f"stages[{i}].walls[{k}]") for i, s in enumerate(case.stages) for k, w in enumerate(s.walls)
    ]


# A wall moved at a prescribed velocity (normal or shear) moves at most this share of the
# smallest radius in a step: the run stops a particle that moves half its radius in one, and a
# wall faster than that drags its particles past it (a velocity typed in m/s for mm/s, or 1e9)
WALL_STEP_SHARE = 0.1


def _moving_wall_limit(case: Case, smallest_radius: float) -> tuple[float, str]:
    """The longest step [s] in which every wall of the case (and of its stages) moved at a
    prescribed velocity covers at most WALL_STEP_SHARE of the smallest radius, with what sets it
    (inf, "" without such walls)."""
    limit, reason = math.inf, ""
    for spec, where in _wall_specs(case):
        motions = [("shear_velocity", spec.shear_velocity)]
        if spec.mode == "velocity":
            motions.append(("velocity", spec.velocity))
        for key, speed in motions:
            if not speed:
                continue
            value = WALL_STEP_SHARE * smallest_radius / abs(speed)
            if value < limit:
                limit = value
                reason = (
                    f"the {spec.face} wall, moved at {where}.{key} = {speed:g} m/s, covers "
                    f"{WALL_STEP_SHARE:g} of the smallest radius ({smallest_radius:.3g} m)"
                )
    return limit, reason


def _restore(loaded: LoadedCase, scene: Scene, restart) -> None:
    if restart.dt != scene.state.clock.dt:
        raise ResumeRefused(
            f"{restart.path}: was written with dt = {restart.dt!r} s but the case now gives "
            f"{scene.state.clock.dt!r} s"
        )
    modules = scene.step.stateful
    optional = set(Scene.OPTIONAL_STATE)
    if set(modules) - optional != set(restart.arrays) - optional:
        raise ResumeRefused(
            f"{restart.path}: holds state for {sorted(restart.arrays)} but the case needs {sorted(modules)}"
        )
    fresh = []
    for name, module in modules.items():
        if name in restart.arrays:
            module.restore(scene.state, restart.arrays[name])
        else:
            fresh.append(module)
    scene.state.clock.step = restart.step
    for module in fresh:  # observed from the resume step on
        module.start()


def _read_once(loaded: LoadedCase, files: dict | None):
    """The case's placement file from `files` (by path; read into it the first time), or None
    without `files` (then _file_particles reads it)."""
    if files is None:
        return None
    placement = loaded.case.particles.placement
    path = particle_file_path(placement, loaded.base_dir).resolve()
    if path not in files:
        files[path] = read_particle_file(placement, loaded.base_dir)
    return files[path]


def _initial_particles(loaded: LoadedCase, rng, files: dict | None = None):
    """(pos, radius, velocity, angular velocity, the placement file or None); `files` as
    check_build's."""
    spec = loaded.case.particles
    velocity = angular_velocity = file = None
    if isinstance(spec.placement, FilePlacement):
        pos, radius, velocity, angular_velocity, file = _file_particles(
            loaded, rng, _read_once(loaded, files)
        )
    else:
        radius = draw_radii(spec.radius, spec.count, rng)
        if isinstance(spec.placement, LatticePlacement):
            pos = lattice_positions(spec.placement, loaded.case, radius, rng)
        elif isinstance(spec.placement, RandomPlacement):
            pos = random_positions(spec.placement, loaded.case, radius, rng)
        else:
            raise TypeError(f"unknown placement {spec.placement!r}")
    if velocity is None:
        velocity = np.tile(np.array(spec.velocity, dtype=np.float64), (radius.size, 1))
    if angular_velocity is None:
        angular_velocity = np.tile(np.array(spec.angular_velocity, dtype=np.float64), (radius.size, 1))
    return (
        np.ascontiguousarray(pos, dtype=np.float64),
        np.ascontiguousarray(radius, dtype=np.float64),
        np.ascontiguousarray(velocity, dtype=np.float64),
        np.ascontiguousarray(angular_velocity, dtype=np.float64),
        file,
    )


def _file_particles(loaded: LoadedCase, rng, file=None):
    """(pos, radius, velocity, angular velocity, the file) of a placement file (`file`, where
    read already), radii drawn where it has none, checked against the box and the memory they
    need."""
    spec = loaded.case.particles
    if file is None:
        file = read_particle_file(spec.placement, loaded.base_dir)
    radius = file.radius if file.radius is not None else draw_radii(spec.radius, file.pos.shape[0], rng)
    # only now are the particles known: the case alone was checked without them
    loc = ("particles", "placement", "path")
    problems = box_problems(loaded.case, 2.0 * float(radius.max()))
    problems += memory_problems(loaded.case, radius.size, float(radius.max()), loc)
    if problems:
        raise loaded.error(*problems[0])
    return file.pos, radius, file.velocity, file.angular_velocity, file


def _file_materials(loaded: LoadedCase, tables: ContactTables, file) -> np.ndarray | None:
    """Material ids from the placement file's material column (None without one: the fractions
    of particles.material deal them)."""
    spec = loaded.case.particles
    column = None if file is None else file.material
    if column is None:
        if isinstance(spec.material, list):
            raise loaded.error(
                ("particles", "material"),
                f"a list of names needs a material column in {spec.placement.path} saying which particle "
                "is made of which; the file has none",
            )
        return None
    if spec.material is None:
        raise loaded.error(
            ("particles", "placement", "path"),
            f"the file's material column names materials ({', '.join(sorted(set(column)))}); list them "
            'in particles.material (material = ["name", ...])',
        )
    ids = {name: k for k, name in enumerate(tables.names)}
    unknown = np.flatnonzero([name not in ids for name in column])
    if unknown.size:
        i = int(unknown[0])
        raise loaded.error(
            ("particles", "placement", "path"),
            f"material column: particle {i} is made of {str(column[i])!r}, which particles.material does not "
            f"name (it names {', '.join(tables.names)}); {unknown.size} particle(s) in all",
        )
    return np.array([ids[name] for name in column], dtype=np.int32)


def _file_groups(loaded: LoadedCase, file) -> tuple:
    """(group names, fixed flags) of the placement file's group and fixed columns, each None
    where the file has none."""
    if file is None:
        return None, None
    if file.group is not None:
        known = {g.name for g in loaded.case.particles.groups if g.name is not None}
        unknown = np.flatnonzero([name != "" and name not in known for name in file.group])
        if unknown.size:
            i = int(unknown[0])
            raise loaded.error(
                ("particles", "placement", "path"),
                f"group column: particle {i} is in group {str(file.group[i])!r}, which no "
                f"particles.groups entry names ({', '.join(sorted(known)) or 'none has a name'}); "
                f"{unknown.size} particle(s) in all",
            )
    return file.group, file.fixed


def _check_inside(loaded: LoadedCase, box: Box, pos: np.ndarray, radius: np.ndarray) -> None:
    """The placed particles (not the glued layers of rough walls, which follow) lie in the box."""
    for a in range(3):
        if box.periodic[a]:
            continue
        outside = np.flatnonzero((pos[:, a] < box.lower[a]) | (pos[:, a] > box.upper[a]))
        if outside.size:
            i = int(outside[0])
            raise loaded.error(
                ("particles", "placement"),
                f"particle {i} starts outside the box along {'xyz'[a]} (at {pos[i, a]:g} m, box "
                f"{box.lower[a]:g} .. {box.upper[a]:g} m); {outside.size} particle(s) in all",
            )
    tol = loaded.case.particles.overlap_tolerance
    for w in loaded.case.walls:
        a = "xyz".index(w.face[0])
        gap = pos[:, a] - box.lower[a] if w.face[1] == "-" else box.upper[a] - pos[:, a]
        deep = np.flatnonzero(radius - gap > tol * radius)
        if deep.size:
            i = int(deep[0])
            raise loaded.error(
                ("particles", "placement"),
                f"particle {i} overlaps the {w.face} wall by {(radius[i] - gap[i]) / radius[i]:.3g} of "
                f"its radius, more than particles.overlap_tolerance = {tol}",
            )


def _check_overlaps(loaded: LoadedCase, state: State) -> None:
    p, box, nl = state.particles, state.box, state.neighbors
    _refuse_overlap(loaded, *worst_overlap(p.pos, p.radius, nl.nbr, nl.nbr_count, box.length, box.periodic))


def _refuse_overlap(loaded: LoadedCase, i: int, j: int, overlap: float) -> None:
    """Refuse particles i and j overlapping by `overlap` of the smaller radius beyond the
    tolerance (run: from the neighbour list; validate: packing.py worst_overlap_of)."""
    tol = loaded.case.particles.overlap_tolerance
    if overlap > tol:
        placement = loaded.case.particles.placement
        source = f" (from {placement.path})" if isinstance(placement, FilePlacement) else ""
        raise loaded.error(
            ("particles", "overlap_tolerance"),
            f"particles {i} and {j}{source} start overlapping by {overlap:.3g} of the smaller radius; "
            "move them apart or raise the tolerance",
        )


def _resolve_dt(
    loaded: LoadedCase,
    dt_limit: float,
    reason: str,
    solid_limit: float,
    bound: tuple[float, str],
    motion: tuple[float, str] = (math.inf, ""),
) -> float:
    """dt of the case, given the stability limit of one contact or a fluid process (and what
    sets it), that of the particles and walls alone, the stability bound with many contacts
    at a sphere (and what sets it), and the longest step the walls' prescribed motion allows
    (and what sets it: _moving_wall_limit) [s]."""
    sim = loaded.case.simulation
    if sim.dt != "auto" and sim.dt > motion[0]:
        raise loaded.error(
            ("simulation", "dt"),
            f"longer than the {motion[0]:.4g} s in which {motion[1]}; "
            f'use dt <= {motion[0]:.4g} s or dt = "auto"',
        )
    if sim.dt == "auto":
        if not math.isfinite(dt_limit):
            raise loaded.error(
                ("simulation", "dt"),
                "no contact can occur (one particle, no walls) and nothing else limits the step, "
                'so "auto" has no limit; give dt in seconds',
            )
        dt = sim.dt_safety * dt_limit
        if dt > AUTO_SHARE * bound[0]:
            dt, reason = AUTO_SHARE * bound[0], f"{AUTO_SHARE:g} x the bound for {bound[1]}"
        if dt > motion[0]:
            dt, reason = motion
        _check_steps(loaded, dt, f'"auto" gives {dt:.3g} s ({reason}): ')
        steps = sim.duration / dt
        if math.isfinite(solid_limit) and dt_limit * FLUID_LIMIT_RATIO < solid_limit:
            viscosity = getattr(loaded.case.fluid, "viscosity", None)
            hint = "" if viscosity is None else f" (fluid.viscosity = {viscosity:g} Pa s)"
            warn(
                loaded.describe(
                    ("simulation", "dt"),
                    f"gives {dt:.3g} s, set by {reason}, {solid_limit / dt_limit:.3g} times below the "
                    f"limit of the particles alone ({solid_limit:.3g} s): {steps:.3g} steps to reach "
                    f"t = {sim.duration:g} s; check the fluid's parameters{hint}",
                )
            )
        elif steps > MANY_STEPS:
            warn(
                loaded.describe(
                    ("simulation", "dt"),
                    f"gives {dt:.3g} s ({reason}): {steps:.3g} steps to reach t = {sim.duration:g} s",
                )
            )
        return dt
    if sim.dt > dt_limit:
        raise loaded.error(
            ("simulation", "dt"),
            f"above the stability limit {dt_limit:.4g} s ({reason}); "
            f'use dt <= {dt_limit:.4g} s or dt = "auto"',
        )
    if sim.dt > bound[0] and sim.stability == "packing":
        raise loaded.error(
            ("simulation", "dt"),
            f"above the stability bound {bound[0]:.4g} s for spheres held by many contacts at once "
            f'({bound[1]}); use dt <= {bound[0]:.4g} s or dt = "auto", or, for a scene that never '
            f'packs densely, simulation.stability = "contact" (up to {dt_limit:.4g} s)',
        )
    _check_steps(loaded, sim.dt)  # the case was checked, but --until may have changed duration
    return float(sim.dt)


def _check_steps(loaded: LoadedCase, dt: float, prefix: str = "") -> None:
    problem = step_problem(loaded.case.simulation.duration, dt)
    if problem is not None:
        raise loaded.error(("simulation", "dt"), prefix + problem)
