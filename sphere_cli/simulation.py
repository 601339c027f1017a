"""The time loop: each step runs the hooks of the scene's modules (physics/module.py, where the
step is listed), then the schedules run.

The run is done when the last stage ends (physics/stages.py) or at its end step. Then:
stability guard (every `blowup_check_every` steps and before
every checkpoint), trajectory frames, observables, checkpoints and status, each on its own
schedule (observables follow the frames unless output.observables sets a schedule of its own).
A stop request (signal, wall-time budget) writes a checkpoint at the end of the burst of steps
under way (about BURST_SECONDS of wall time).
"""

from __future__ import annotations

import time as wallclock
from dataclasses import dataclass, field

from .errors import NumericalError
from .runtime import StopFlag

REASONS = {
    1: ("a non-finite position or velocity", 'a smaller dt (or dt = "auto") or softer contacts may help'),
    2: (
        "it moves more than half its radius in one step",
        'a smaller dt (or dt = "auto") or softer contacts may help',
    ),
    3: (
        "it left the box through an open face",
        "enlarge the box, add a wall on that face, or make the axis periodic",
    ),
}


@dataclass
class StepSchedule:
    """Fires every n steps, and/or every `wall_seconds` of wall-clock time."""

    every_steps: int | None = None
    wall_seconds: float | None = None
    last_wall: float = field(default_factory=wallclock.monotonic)

    @classmethod
    def from_config(cls, schedule, clock) -> StepSchedule:
        steps = schedule.every_steps
        if schedule.every_time is not None:
            by_time = clock.steps_in(schedule.every_time)
            steps = by_time if steps is None else min(steps, by_time)
        wall = schedule.every_wall_minutes * 60.0 if schedule.every_wall_minutes else None
        return cls(every_steps=steps, wall_seconds=wall)

    def due(self, step: int, now: float) -> bool:
        if self.every_steps is not None and step % self.every_steps == 0:
            return True
        return self.wall_seconds is not None and now - self.last_wall >= self.wall_seconds

    def done(self, now: float) -> None:
        self.last_wall = now


def advance(scene, steps: int, sync: bool = True) -> bool:
    """Advance the scene by `steps` steps with no output (library use and tests), or until the
    last stage ends. Returns True if a stage ended on the last step taken. On a GPU
    (physics/device_steps.py) the host's arrays hold the result once `sync` brings it back, and
    changes made to them before the next call are then taken up (`hand_over`; the run loop
    brings the state back only when it reads it: `to_host`).

    Where the scene's step allows it (physics/compiled_steps.py), whole runs of steps up to the
    next after_step hook are taken in one compiled call; the step that makes the neighbour list
    stale is finished here with the hooks. The result is bitwise the same either way."""
    state = scene.state
    step = scene.step
    kick_drift, prepare, forces, kick = step.kick_drift, step.prepare, step.forces, step.kick
    finish_step, after_step = step.finish_step, step.after_step
    compiled = step.compiled
    clock = state.clock

    def after() -> None:
        for module, hook in after_step:
            if module.after_due(clock.step, clock):
                hook(state)

    taken = 0
    while taken < steps and not scene.finished:
        drifted = False
        if compiled is not None:
            # no after_step hook runs before the last of these steps
            run = min([steps - taken] + [m.steps_to_after(clock.step, clock) for m, _ in after_step])
            if run > 1 or compiled.whole_steps:
                done, drifted = compiled.run(state, run)
                if done:
                    clock.step += done
                    taken += done
                    # only the last whole step can be a coupling step (run bounds it); when the
                    # next step's kick-drift is already done, that one is not
                    after()
                if not drifted:
                    continue
        if not drifted:
            for hook in kick_drift:
                hook(state)
        for hook in prepare:
            hook(state)
        for hook in forces:
            hook(state)
        for hook in kick:
            hook(state)
        for hook in finish_step:
            hook(state)
        clock.step += 1
        taken += 1
        after()
    if sync:
        hand_over(scene)
    return scene.stages is not None and scene.stages.ended_at == clock.step


def to_host(scene) -> None:
    """The state into the host's arrays, where steps run elsewhere (a GPU), for reading."""
    if scene.step.compiled is not None:
        scene.step.compiled.to_host(scene.state)


def hand_over(scene) -> None:
    """The state into the host's arrays for a caller who may change them before the next steps
    (a script or notebook between calls of advance): steps that run elsewhere take them up
    again from the host."""
    if scene.step.compiled is not None:
        scene.step.compiled.hand_over(scene.state)


def check_stable(scene) -> None:
    """Raise NumericalError naming step, time and particle if the state has gone bad. A GPU checks
    its own state first and brings it back only when something has gone bad."""
    compiled = scene.step.compiled
    if compiled is not None and compiled.known_stable(scene.state):
        return
    to_host(scene)
    clock = scene.state.clock
    if scene.fluid is not None:
        problem = scene.fluid.first_unstable(scene.state)
        if problem is not None:
            raise NumericalError(
                f"numerical failure at step {clock.step} (t = {clock.time:.6g} s) in the fluid: {problem}. "
                "The newest checkpoint before this step is intact; a smaller dt or a finer coupling "
                "interval may help."
            )
    if scene.motion is None:  # no particles
        return
    i, reason = scene.motion.first_unstable(scene.state)
    if i >= 0:
        p = scene.state.particles
        what, hint = REASONS[reason]
        face = _face_left(scene, i) if reason == 3 else None
        if face is not None and any(w.face == face for w in scene.case.walls):
            what = f"it passed through the wall on face {face} and left the box"
            hint = (
                "the wall's contact is too soft for the particle's weight and speed: stiffen it (or, "
                'with dt given in seconds, try dt = "auto")'
            )
        raise NumericalError(
            f"numerical failure at step {clock.step} (t = {clock.time:.6g} s): particle {i} at "
            f"{tuple(float(x) for x in p.pos[i])} m with velocity {tuple(float(x) for x in p.vel[i])} "
            f"m/s: {what}. The newest checkpoint before this step is intact; {hint}."
        )


def _face_left(scene, i: int) -> str | None:
    """The face of the box ("z-", ...) that particle i is beyond by more than its radius, on an
    axis that is not periodic; None if none."""
    box, p = scene.state.box, scene.state.particles
    r = float(p.radius[i])
    for a in range(3):
        if box.periodic[a]:
            continue
        if p.pos[i, a] < box.lower[a] - r:
            return f"{'xyz'[a]}-"
        if p.pos[i, a] > box.upper[a] + r:
            return f"{'xyz'[a]}+"
    return None


# The loop takes steps in bursts of about this much wall time [s] (at most MAX_BURST steps)
# between its looks at the stop flag and the wall-clock schedules.
BURST_SECONDS = 0.05
MAX_BURST = 10_000


class Loop:
    """Runs a scene to `end_step`, calling back into the run directory for output."""

    def __init__(
        self, scene, end_step: int, output, stop: StopFlag, max_wall_seconds: float | None, progress
    ):
        self.scene = scene
        self.end_step = end_step
        self.output = output
        self.stop = stop
        self.max_wall_seconds = max_wall_seconds
        self.progress = progress
        clock = scene.state.clock
        out_cfg = scene.case.output
        self.frames = StepSchedule.from_config(out_cfg.frames, clock)
        self.checkpoints = StepSchedule.from_config(out_cfg.checkpoints, clock)
        observed = out_cfg.observables
        self.observations = None if observed.follows_frames else StepSchedule.from_config(observed, clock)
        self.status = StepSchedule(wall_seconds=progress.interval)
        self.check_every = scene.case.simulation.blowup_check_every
        # steps per call of advance, grown from the measured rate; the first call takes two, so
        # that the compiled steps (physics/compiled_steps.py) compile before the progress rate starts
        self.burst = 2

    def _next_stop(self, step: int) -> int:
        """The next step with something on a step schedule (frames, observables, checkpoints,
        the stability check) or the end step."""
        stop = self.end_step
        every = [self.frames.every_steps, self.checkpoints.every_steps, self.check_every]
        if self.observations is not None:
            every.append(self.observations.every_steps)
        for n in every:
            if n:
                stop = min(stop, (step // n + 1) * n)
        stages = self.scene.stages
        if stages is not None and not stages.finished:  # a stage ends only where it may end
            stop = min(stop, step + stages.steps_to_after(step, self.scene.state.clock))
        return stop

    def run(self) -> str:
        """Returns "done" or the stop reason."""
        scene = self.scene
        state = scene.state
        clock = state.clock
        started = wallclock.monotonic()
        while clock.step < self.end_step and not scene.finished:
            if self.stop.interrupted:
                raise KeyboardInterrupt
            if self.stop.reason is not None:
                break
            if self.max_wall_seconds is not None and wallclock.monotonic() - started >= self.max_wall_seconds:
                self.stop.request("wall-time budget (--max-wall-time) reached")
                break
            # up to the next step the loop must look at (_next_stop: a schedule's, or one where a
            # stage may end), in bursts of about BURST_SECONDS so that stop requests and
            # wall-clock schedules are seen as promptly as step by step
            burst = min(self._next_stop(clock.step) - clock.step, self.burst)
            burst_start = wallclock.monotonic()
            stage_ended = advance(scene, burst, sync=False)
            elapsed = wallclock.monotonic() - burst_start
            self.burst = max(1, min(MAX_BURST, int(BURST_SECONDS * burst / max(elapsed, 1e-9))))
            step = clock.step
            first = self.progress.rate_start is None
            if first:
                self.progress.first_step_done(step)
            if stage_ended:
                to_host(scene)
                self._stage_ended(scene)
            if step % self.check_every == 0:
                check_stable(scene)
            now = wallclock.monotonic()
            if self.frames.due(step, now):
                to_host(scene)
                check_stable(scene)  # no frame with NaNs reaches the trajectory
                self.output.frame(scene)
                self.frames.done(now)
            if self.observations is not None and self.observations.due(step, now):
                to_host(scene)
                self.output.observe(scene)
                self.observations.done(now)
            if self.checkpoints.due(step, now) and step < self.end_step:
                to_host(scene)
                check_stable(scene)
                self.output.checkpoint(scene)
                self.checkpoints.done(now)
            # the first steps taken, status.json says "running" at once, not only a status
            # interval later (until then it said "starting": building the scene)
            if first or self.status.due(step, now):
                self.progress.update(scene, now - started)
                self.status.done(now)
        if self.stop.interrupted:
            raise KeyboardInterrupt
        to_host(scene)
        check_stable(scene)
        self.output.frame(scene, last=True)
        if self.observations is not None:
            self.output.observe(scene)
        self.output.checkpoint(scene)
        finished = clock.step >= self.end_step or scene.finished
        self.progress.update(scene, wallclock.monotonic() - started, state="done" if finished else "stopped")
        return "done" if finished else self.stop.reason

    def _stage_ended(self, scene) -> None:
        """A stage ended at this step: frame and checkpoint (a resume can start any stage)."""
        stages = scene.stages
        clock = scene.state.clock
        log = getattr(self.output, "log", None)
        if log is not None:
            ended = stages.names[stages.index - 1]
            now = stages.current
            log.info("stage %r ended at step %d (t = %.6g s); now: %s", ended, clock.step, clock.time, now)
        check_stable(scene)
        self.output.frame(scene)
        self.output.checkpoint(scene)
