"""The DEM steps run many at a time in one compiled call (kernels/steps.py), bitwise the same as
the hooks one step at a time, without the interpreter's ~18 us a step.

It applies when the step is exactly: the particles' kick-drift, the neighbour search, the pair
contacts, optionally the plane-wall contacts, optionally one more force: a fluid's that is one
kernel (`force_loops`, and `force_arguments` for it: the 1D VANS fluid's, in its variant of
kernels/steps.py dem_steps), or that of a module with a compiled loop of its own
(`steps_kernel`: the Navier-Stokes drag's), then the particles' kick or that module's own where
it takes the kick over (`kick_arguments` for it: the Navier-Stokes drag's exact kick), and
nothing after the kick (physics/module.py) but the energy budget's booking; the module's
`steps_taken` then reports what its loop found (the Navier-Stokes drag's porosity floor). The
walls' motion (moving or stress-controlled walls, their kick-drift and kick around the
particles') may be in either loop, and with dem_steps (no module loop of its own) the energy
budget (its forces hook first of the forces, its finish_step the only one). Anything else in
the step (another force, a module loop with the budget, a hook replaced by a wrapper) keeps
the step-by-step loop.
simulation.advance bounds each call by the next step where an after_step hook runs (a fluid's
coupling, a step where a stage may end), so those run in Python.
"""

from __future__ import annotations

from ..kernels.serial import use_serial
from ..kernels.steps import dem_steps, dem_steps_serial
from ..state import State
from .contact import PairContactForces
from .module import Step
from .motion import Motion
from .neighbors import NeighborSearch
from .observe.energy_budget import EnergyBudget
from .walls import PlaneWallForces, WallMotion


def _own(hook, name: str) -> bool:
    """True if `hook` is its owner's class's own method `name` (not a wrapper put on it)."""
    owner = getattr(hook, "__self__", None)
    return owner is not None and getattr(hook, "__func__", None) is getattr(type(owner), name, None)


def is_hook_of(hook, cls, name: str) -> bool:
    """True if `hook` is cls's own method `name`, bound to an instance of exactly cls."""
    return type(getattr(hook, "__self__", None)) is cls and _own(hook, name)


def _declared_with_forces(hook, attribute: str) -> bool:
    """True if `hook` is the forces method of the class that sets `attribute` (not None)
    beside it (`steps_kernel`, `force_loops`): a subclass with forces of its own does not
    inherit what the attribute says of them."""
    if not _own(hook, "forces"):
        return False
    cls = type(hook.__self__)
    for base in cls.__mro__:
        if attribute in vars(base):
            return vars(base)[attribute] is not None and vars(base).get("forces") is cls.forces
    return False


def plain_step(scene, budget: bool = False) -> bool:
    """True if the scene's hooks are exactly its modules' own (the particles' motion, walls that
    move, the search, the pair and wall contacts, a fluid's force and kick, stages and a fluid's
    step between steps; with `budget`, the energy budget's too), none replaced by a wrapper: the
    steps that the ranks (physics/rank_steps.py) and a GPU (physics/device_steps.py) take in
    their own order."""
    step = scene.step
    kept = scene.budget if budget else None
    moving = () if scene.wall_motion is None else (scene.wall_motion,)
    fluid_kicks = scene.fluid is not None and "kick" in scene.fluid.takes_over
    kicks = [(m, WallMotion) for m in moving]
    kicks.append((scene.fluid, type(scene.fluid)) if fluid_kicks else (scene.motion, Motion))
    forces = [(scene.contact, PairContactForces)]
    if kept is not None:  # its forces hook first: it keeps the springs of the last step
        forces.insert(0, (kept, type(kept)))
    if scene.walls is not None:
        forces.append((scene.walls, PlaneWallForces))
    if scene.fluid is not None:
        forces.append((scene.fluid, type(scene.fluid)))
    expected = {
        "kick_drift": [(m, WallMotion if m is not scene.motion else Motion) for m in (*moving, scene.motion)],
        "prepare": [(scene.neighbors, NeighborSearch)],
        "forces": forces,
        "kick": kicks,
    }
    for hook, modules in expected.items():
        hooks = getattr(step, hook)
        if len(hooks) != len(modules):
            return False
        for bound, (module, cls) in zip(hooks, modules, strict=True):
            if getattr(bound, "__self__", None) is not module or not is_hook_of(bound, cls, hook):
                return False
    finish = () if kept is None else (kept.finish_step,)
    return tuple(step.finish_step) == finish and all(
        m is scene.stages or m is scene.fluid for m, _ in step.after_step
    )


def step_arguments(state: State, contact: PairContactForces, walls: PlaneWallForces | None) -> tuple:
    """The argument tuples of the DEM step's kernels (kernels/steps.py): (kick_drift's, those of
    cross_chunk_pairs and chunk_pair_forces, wall_forces' or None without walls, kick's), valid
    until the next list build while the walls stay where they are."""
    cross, pairs = contact.kernel_arguments(state)
    wall = None if walls is None else walls.kernel_arguments(state)
    return Motion.drift_arguments(state), cross, pairs, wall, Motion.kick_arguments(state)


class CompiledSteps:
    # a single step is taken by the hooks (the loop's call costs more than it saves)
    whole_steps = False

    def __init__(
        self, search: NeighborSearch, contact: PairContactForces, walls, extra, moving: bool = False,
        budget: EnergyBudget | None = None, fluid=None,
    ):  # fmt: skip
        self.search, self.contact, self.walls, self.extra = search, contact, walls, extra
        self.moving = moving  # the walls' motion in the loop
        self.budget = budget  # the energy budget's hooks in the loop
        self.fluid = fluid  # a fluid whose force is in its variant of dem_steps (force_loops)

    @classmethod
    def of(cls, step: Step) -> CompiledSteps | None:
        """The compiled steps for this step's hooks, or None where they do not apply."""
        forces, kick_drift, kick = list(step.forces), list(step.kick_drift), list(step.kick)
        moving = (
            len(kick_drift) == 2
            and is_hook_of(kick_drift[0], WallMotion, "kick_drift")
            and len(kick) == 2
            and is_hook_of(kick[0], WallMotion, "kick")
        )
        if moving:
            kick_drift, kick = kick_drift[1:], kick[1:]
        budget, finish = None, list(step.finish_step)
        if forces and is_hook_of(forces[0], EnergyBudget, "forces"):  # it runs first of the forces
            budget = forces.pop(0).__self__
            if finish != [budget.finish_step] or not is_hook_of(finish[0], EnergyBudget, "finish_step"):
                return None
            finish = []
        if not (
            len(kick_drift) == 1
            and is_hook_of(kick_drift[0], Motion, "kick_drift")
            and len(step.prepare) == 1
            and is_hook_of(step.prepare[0], NeighborSearch, "prepare")
            and forces
            and is_hook_of(forces[0], PairContactForces, "forces")
            and len(kick) == 1
            and not finish
        ):
            return None
        contact, walls, extra = forces.pop(0).__self__, None, None
        if forces and is_hook_of(forces[0], PlaneWallForces, "forces"):
            walls = forces.pop(0).__self__
        fluid = None
        if forces and _declared_with_forces(forces[0], "steps_kernel"):
            extra = forces.pop(0).__self__
        elif forces and _declared_with_forces(forces[0], "force_loops"):
            fluid = forces.pop(0).__self__
        if forces or (moving and walls is None) or (budget and extra is not None):
            return None
        # the kick: the particles' own, or that of the module whose loop kicks them itself
        if extra is not None and "kick" in extra.takes_over:
            kicks_own = kick[0].__self__ is extra and is_hook_of(kick[0], type(extra), "kick")
        else:
            kicks_own = is_hook_of(kick[0], Motion, "kick")
        if not kicks_own:
            return None
        return cls(step.prepare[0].__self__, contact, walls, extra, moving, budget, fluid)

    @staticmethod
    def to_host(state: State) -> None:
        """Nothing to bring back: the state is the host's arrays (physics/device_steps.py)."""

    hand_over = to_host  # the caller's changes are the state's already

    @staticmethod
    def known_stable(state: State) -> bool:
        """False: the host checks its own arrays (simulation.check_stable)."""
        return False

    def run(self, state: State, steps: int) -> tuple[int, bool]:
        """Take up to `steps` whole steps; stop early after a kick-drift that makes the neighbour
        list stale. Returns (the whole steps taken, True if that kick-drift ended the call: the
        caller finishes that step with the hooks, from `prepare` on)."""
        drift, cross, pairs, walls, kicks = step_arguments(state, self.contact, self.walls)
        threshold2 = self.search.threshold2
        serial = use_serial()  # without parallel regions (kernels/serial.py)
        motion = None
        if self.moving:
            clock = state.clock
            # walls.kernel_arguments above made the near-wall list at the walls' positions now
            listed_at, reach = self.walls.near_list_made_at(state)
            drift_walls, areas, totals, wall_kick = WallMotion.kernel_arguments(state)
            totals = (state.walls.listed, *totals)  # listed_wall_totals's
            motion = (drift_walls, areas, totals, wall_kick, listed_at, reach, clock.step, clock.dt)
        if self.extra is None:
            budget = None
            if self.budget is not None:  # the arguments of its two hooks
                budget = (self.budget.keep_arguments(state), self.budget.book_arguments(state))
            fluid, loop = None, dem_steps_serial if serial else dem_steps
            if self.fluid is not None:  # its variant of the loop, with its force in it
                fluid, loop = self.fluid.force_arguments(state), self.fluid.force_loops[1 if serial else 0]
            # with several chunks, each one's walls after its pairs (kernels/steps.py chunk_steps_end)
            chunked = None
            if cross is not None and walls is not None:
                chunked = PlaneWallForces.by_chunks(walls, self.contact.bounds)
            done, moved2, drifted = loop(
                steps, threshold2, drift, cross, pairs, walls, fluid, kicks, motion, budget, chunked
            )
        else:
            extra = self.extra.force_arguments(state)
            if "kick" in self.extra.takes_over:
                kicks = self.extra.kick_arguments(state)
            twin = getattr(self.extra, "serial_steps_kernel", None)
            loop = twin if serial and twin is not None else self.extra.steps_kernel
            done, moved2, drifted = loop(steps, threshold2, drift, cross, pairs, walls, extra, kicks, motion)
            self.extra.steps_taken(state, int(done))
        state.neighbors.moved2 = moved2
        return int(done), bool(drifted)
