"""The module protocol: every part of a scene's step is a `Module`, and the step is built once.

The builder (scene/builder.py) returns the scene's modules as one ordered tuple; `Step` takes,
for each hook, the bound methods of the modules whose class defines it, in that order, and the
loop (simulation.py) runs those flat tuples. A module that does not define a hook is not
called for it; a process the case does not have is not in the tuple at all.

One step of velocity Verlet, in the order the loop runs the hooks:

    1. kick_drift   first half kick and drift (walls, then particles)
    2. prepare      the neighbour list, rebuilt when the particles have moved far enough
    3. forces       forces and torques at the new positions
    4. kick         second half kick (walls, then particles, or a fluid that takes it over)
    5. finish_step  what needs the full-step velocities (the energy budget)
    6. the clock advances one step
    7. after_step   where `after_due`: the fluid's own step (every `coupling_steps` steps), the
                    stages' end test (where a stage's duration ends or its stop_when is tested)

Beside the step: `prognostic_state`/`restore` (everything a bitwise restart needs, written to
the checkpoint group `name`), `observables` (scalars and arrays of the output schedule) and
`dt_limit` (a fluid model's limit on the step, read while the scene is built; the contact and
wall limits need the whole scene and are functions of physics/contact.py and physics/walls.py).
"""

from __future__ import annotations

import math

import numpy as np

# the hooks of one step, in the order they run (the clock advances before after_step)
STEP_HOOKS = ("kick_drift", "prepare", "forces", "kick", "finish_step", "after_step")

# (first, then, hook, why): where both modules are in a scene and define the hook, `first`
# runs before `then` (checked by tests/unit/test_step.py on every example case)
ORDER = (
    ("wall_motion", "particles", "kick_drift", "glued particles drift with the wall's new velocity"),
    ("energy_budget", "contact", "forces", "the budget keeps the springs of the last step first"),
    ("contact", "walls", "forces", "the pair sweep sets each force (gravity, pairs); others add"),
    ("contact", "fluid", "forces", "the pair sweep sets each force (gravity, pairs); others add"),
    ("wall_motion", "fluid", "kick", "the walls' totals read the forces before the fluid's kick"),
    ("fluid", "stages", "after_step", "the fluid steps before a new stage moves the walls"),
)


class Module:
    """Base class of every module of the step; each hook's default does nothing and is skipped."""

    # the checkpoint group of the prognostic state, and the name ORDER refers to
    name = ""
    # after_step runs every this many steps (a fluid's coupling interval, set once dt is known)
    coupling_steps = 1
    # hooks of other modules this one runs instead, {hook: module name} (a fluid with implicit
    # drag takes the particles' second half kick)
    takes_over: dict[str, str] = {}
    # its hooks that act on the particles alone: a scene without particles (a fluid-only one)
    # leaves them out of the step
    particle_hooks: tuple[str, ...] = ()

    def kick_drift(self, state) -> None:
        """First half kick and drift."""

    def prepare(self, state) -> None:
        """Before the forces: the neighbour list."""

    def forces(self, state, spring_dt: float | None = None) -> None:
        """Add forces and torques at the current positions; `spring_dt` = 0 for the forces of
        the initial state (no time has passed, tangential springs do not grow)."""

    def kick(self, state) -> None:
        """Second half kick."""

    def finish_step(self, state) -> None:
        """After the second half kick, before the clock advances."""

    def after_step(self, state) -> None:
        """After the clock advances, at the steps where after_due."""

    def after_due(self, step: int, clock) -> bool:
        """True if after_step runs after `step` (the clock's step once it has advanced)."""
        return step % self.coupling_steps == 0

    def steps_to_after(self, step: int, clock) -> int:
        """The steps from `step` to the next one where after_due (>= 1): the loop takes them in
        one compiled call (physics/compiled_steps.py)."""
        return self.coupling_steps - step % self.coupling_steps

    def prognostic_state(self, state) -> dict[str, np.ndarray]:
        """Everything a bitwise restart needs (scalars as 0-d arrays)."""
        return {}

    def restore(self, state, arrays: dict) -> None:
        """Put back what prognostic_state() returned."""

    def observables(self, state) -> dict[str, tuple]:
        """name -> (value, unit) of the output schedule."""
        return {}

    def dt_limit(self) -> tuple[float, str]:
        """The most restrictive limit on the step [s] and a phrase naming it."""
        return math.inf, ""


HOOKS = (*STEP_HOOKS, "prognostic_state", "restore", "observables", "dt_limit")


def defines(module, hook: str) -> bool:
    """True when the module has a `hook` of its own (not the protocol's do-nothing default)."""
    own = getattr(module, hook, None)
    return own is not None and getattr(own, "__func__", own) is not getattr(Module, hook)


def order_problems(modules) -> list[str]:
    """Each ORDER constraint that the ordered `modules` break, in words (none: an empty list)."""
    position = {m.name: k for k, m in enumerate(modules) if m.name}
    taken = {(name, hook) for m in modules for hook, name in m.takes_over.items()}
    problems = []
    for first, then, hook, why in ORDER:
        if first in position and then in position:
            a, b = modules[position[first]], modules[position[then]]
            runs = all(defines(m, hook) and (m.name, hook) not in taken for m in (a, b))
            if runs and position[first] > position[then]:
                problems.append(f"{first}.{hook} must run before {then}.{hook}: {why}")
    return problems


class Step:
    """The bound methods of each step hook, taken once from the scene's ordered modules; without
    `particles` (a fluid-only scene), the hooks a module lists in particle_hooks are left out."""

    def __init__(self, modules: tuple, particles: bool = True):
        taken = {(name, hook) for m in modules for hook, name in m.takes_over.items()}

        def bound(hook: str) -> tuple:
            return tuple(
                getattr(m, hook)
                for m in modules
                if defines(m, hook)
                and (m.name, hook) not in taken
                and (particles or hook not in m.particle_hooks)
            )

        self.kick_drift = bound("kick_drift")
        self.prepare = bound("prepare")
        self.forces = bound("forces")
        self.kick = bound("kick")
        self.finish_step = bound("finish_step")
        # with the module: its after_due is asked at each step (a fluid sets its coupling_steps
        # in start())
        self.after_step = tuple((m, m.after_step) for m in modules if defines(m, "after_step"))
        self.stateful = {m.name: m for m in modules if defines(m, "prognostic_state") and m.name}
        self.observed = tuple(m.observables for m in modules if defines(m, "observables"))
        # many steps in one compiled call where the hooks allow it (physics/compiled_steps.py,
        # set by the scene once its modules are ordered)
        self.compiled = None
