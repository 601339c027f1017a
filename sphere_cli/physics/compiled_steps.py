"""The steps of a dry DEM scene run many at a time in one compiled call (kernels/steps.py),
bitwise the same as the hooks one step at a time, without the interpreter's ~18 us a step.

It applies when the step is exactly: the particles' kick-drift, the neighbour search, the pair
contacts and (optionally) the plane-wall contacts, the particles' kick, and nothing after the
kick (physics/module.py). Anything else in the step (a fluid, moving walls, the energy budget, a
hook replaced by a wrapper) keeps the step-by-step loop. simulation.advance bounds each call by
the next step where an after_step hook runs (stages, every step), so those still run in Python.
"""

from __future__ import annotations

from ..kernels.steps import dry_steps
from ..state import State
from .contact import PairContactForces
from .module import Step
from .motion import Motion
from .neighbors import NeighborSearch
from .walls import PlaneWallForces


def _is(hook, cls, name: str) -> bool:
    """True if `hook` is cls's own method `name`, bound to an instance of exactly cls."""
    return type(getattr(hook, "__self__", None)) is cls and getattr(hook, "__func__", None) is getattr(
        cls, name
    )


class CompiledSteps:
    def __init__(self, search: NeighborSearch, contact: PairContactForces, walls: PlaneWallForces | None):
        self.search, self.contact, self.walls = search, contact, walls

    @classmethod
    def of(cls, step: Step) -> CompiledSteps | None:
        """The compiled steps for this step's hooks, or None where they do not apply."""
        if not (
            len(step.kick_drift) == 1
            and _is(step.kick_drift[0], Motion, "kick_drift")
            and len(step.prepare) == 1
            and _is(step.prepare[0], NeighborSearch, "prepare")
            and len(step.forces) in (1, 2)
            and _is(step.forces[0], PairContactForces, "forces")
            and all(_is(hook, PlaneWallForces, "forces") for hook in step.forces[1:])
            and len(step.kick) == 1
            and _is(step.kick[0], Motion, "kick")
            and not step.finish_step
        ):
            return None
        walls = step.forces[1].__self__ if len(step.forces) == 2 else None
        return cls(step.prepare[0].__self__, step.forces[0].__self__, walls)

    def run(self, state: State, steps: int) -> tuple[int, bool]:
        """Take up to `steps` whole steps; stop early after a kick-drift that makes the neighbour
        list stale. Returns (the whole steps taken, True if that kick-drift ended the call: the
        caller finishes that step with the hooks, from `prepare` on)."""
        cross, pairs = self.contact.kernel_arguments(state)
        walls = None if self.walls is None else self.walls.kernel_arguments(state)
        drift, kicks = Motion.drift_arguments(state), Motion.kick_arguments(state)
        done, moved2, drifted = dry_steps(steps, self.search.threshold2, drift, cross, pairs, walls, kicks)
        state.neighbors.moved2 = moved2
        return int(done), bool(drifted)
