"""Chained stages of an experiment (deposit -> consolidate -> shear) in one run.

Stage k starts at the step stage k-1 ended on. On entry the walls it lists take their new mode
(the others keep theirs; before the first stage they have the modes of [[walls]]), the contact
friction becomes the stage's (or the tables' own), and the wall positions are noted for its
displacement criteria. A stage ends when its duration has passed or, tested every check_every
steps, a stop_when condition holds; after the last one the run is finished.

Everything a resume needs is the stage index, its first step and the wall positions then
(prognostic_state); the modes and the friction follow from the case.
"""

from __future__ import annotations

import numpy as np

from ..kernels.laws import MU
from ..kernels.observe.energy import kinetic_energy
from ..state import State
from .module import Module
from .walls import apply_modes


def approach(state: State, w: int) -> None:
    """Move wall w (and the particles glued to it) along its normal until its plane, or its
    rough layer, just touches the outermost free particle."""
    p, walls = state.particles, state.walls
    a, sign = walls.axis[w], walls.sign[w]
    free = p.inv_mass > 0.0
    if not np.any(free):
        return
    glued = walls.attached[walls.attached_wall == w]
    reach = float(p.radius[glued].max()) if glued.size else 0.0
    # sign * (x - coord) is the distance into the box; the outermost particle has the smallest
    surface = p.pos[free, a] - sign * p.radius[free]
    target = (surface.min() if sign > 0 else surface.max()) - sign * reach
    step = target - walls.coord[w]
    walls.coord[w] = target
    walls.shift[w, a] += step
    p.pos[glued, a] += step


class Stages(Module):
    name = "stages"

    def __init__(self, case, walls_state, scales, contact):
        self.stages = case.stages
        self.names = [s.name or f"stage {k}" for k, s in enumerate(self.stages)]
        self.face_index = {spec.face: w for w, spec in enumerate(case.walls)}
        self.base = dict(enumerate(case.walls))
        self.scales = scales
        self.contact = contact
        self.pair_mu = contact.table[..., MU].copy()
        self.wall_mu = None if walls_state is None else walls_state.table[..., MU].copy()
        nw = 0 if walls_state is None else len(walls_state.faces)
        self.index = 0
        self.ended_at = -1  # the step where a stage last ended (-1: none yet in this process)
        self.start_step = 0
        self.start_coord = np.zeros(nw)
        self.start_shift = np.zeros((nw, 3))

    @property
    def finished(self) -> bool:
        return self.index >= len(self.stages)

    @property
    def current(self) -> str:
        return "finished" if self.finished else self.names[self.index]

    def modes(self, k: int) -> dict:
        """Wall index -> mode in force during stage k."""
        modes = dict(self.base)
        for stage in self.stages[: k + 1]:
            for spec in stage.walls:
                modes[self.face_index[spec.face]] = spec
        return modes

    def begin(self, state: State, k: int) -> None:
        """Enter stage k at the current step."""
        self.index = k
        self.start_step = state.clock.step
        if state.walls is not None and not self.finished:
            for spec in self.stages[k].walls:
                if spec.approach:
                    approach(state, self.face_index[spec.face])
        if state.walls is not None:
            self.start_coord[:] = state.walls.coord
            self.start_shift[:] = state.walls.shift
        self._apply(state)

    def _apply(self, state: State) -> None:
        if self.finished:
            return
        stage = self.stages[self.index]
        friction = stage.friction
        self.contact.table[..., MU] = self.pair_mu if friction is None else friction
        walls = state.walls
        if walls is not None:
            walls.table[..., MU] = self.wall_mu if friction is None else friction
            apply_modes(
                walls,
                self.modes(self.index),
                self.scales,
                state.box,
                self.start_step * state.clock.dt,
                self.start_coord,
            )

    def after_step(self, state: State) -> None:
        """Test the current stage's end; `ended_at` is this step if a stage ended at it."""
        if self.ends_at(state.clock.step, state):
            self.begin(state, self.index + 1)
            self.ended_at = state.clock.step

    def ends_at(self, step: int, state: State) -> bool:
        """Whether the current stage ends at `step` (the clock's, once it has advanced there): its
        duration is over, or its stop_when holds on the particles' velocities and spins and the
        walls' positions and shifts in `state`, all that the test reads (a GPU brings back only
        those for a test, and the whole state where the stage ends)."""
        over, tested = self._due(step, state.clock)
        if over or not tested:
            return over
        return self._condition_met(state, self.stages[self.index].stop_when, step - self.start_step)

    def after_due(self, step: int, clock) -> bool:
        """True if after_step at `step` may end the current stage (its duration ends there, or a
        stop_when condition is tested there): the only steps where it reads the state, or
        changes it (physics/rank_steps.py brings the state back to the lead for these)."""
        return any(self._due(step, clock))

    def steps_to_after(self, step: int, clock) -> int:
        """The steps from `step` to the next one where the current stage may end (a large number
        once every stage has finished)."""
        if self.finished:
            return 1 << 62
        stage = self.stages[self.index]
        elapsed = step - self.start_step
        ahead = [1 << 62]
        if stage.duration is not None:
            ahead.append(max(1, clock.steps_in(stage.duration) - elapsed))
        if stage.stop_when is not None:
            ahead.append(stage.check_every - elapsed % stage.check_every)
        return min(ahead)

    def _due(self, step: int, clock) -> tuple[bool, bool]:
        """At `step`: (the current stage's duration is over, its stop_when is tested); both
        False once every stage has finished."""
        if self.finished:
            return False, False
        stage = self.stages[self.index]
        elapsed = step - self.start_step
        over = stage.duration is not None and elapsed >= clock.steps_in(stage.duration)
        return over, stage.stop_when is not None and elapsed % stage.check_every == 0

    def _condition_met(self, state: State, stop, elapsed: int) -> bool:
        if stop.kinetic_energy_below is not None and elapsed * state.clock.dt >= stop.min_time:
            p = state.particles
            if kinetic_energy(p.vel, p.angvel, p.mass, p.inertia) < stop.kinetic_energy_below:
                return True
        if stop.wall is not None:
            w = self.face_index[stop.wall]
            walls = state.walls
            moved = walls.shift[w] - self.start_shift[w]
            a = walls.axis[w]
            normal = abs(walls.coord[w] - self.start_coord[w])
            tangential = float(np.sqrt(np.sum(moved**2) - moved[a] ** 2))
            if stop.displacement is not None and normal >= stop.displacement:
                return True
            if stop.shear_displacement is not None and tangential >= stop.shear_displacement:
                return True
        return False

    def observables(self, state: State) -> dict:
        # after the last stage ends (the run's end frame) the state is still the last stage's
        return {"stage": (float(min(self.index, len(self.stages) - 1)), "")}

    def prognostic_state(self, state: State) -> dict:
        return {
            "index": np.int64(self.index),
            "start_step": np.int64(self.start_step),
            "start_coord": self.start_coord,
            "start_shift": self.start_shift,
        }

    def restore(self, state: State, arrays: dict) -> None:
        self.index = int(arrays["index"])
        self.start_step = int(arrays["start_step"])
        self.start_coord[:] = arrays["start_coord"]
        self.start_shift[:] = arrays["start_shift"]
        self._apply(state)
