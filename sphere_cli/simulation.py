"""The time loop: one step composes only the modules the scene holds, then the schedules run.

Step (velocity Verlet):  kick-drift  ->  prepare (neighbour list)  ->  forces  ->  kick
->  finish (modules that need the full-step velocities: the energy budget), then, with a fluid,
the fluid's own step when it is due (physics/fluid.py). Moving walls are kicked and drifted
just before the particles (their glued particles take the wall's velocity) and kicked after the
forces. After the clock advances the stages test their end (physics/stages.py); the run is done
when the last stage ends. Then: stability guard (every `blowup_check_every` steps and before
every checkpoint), trajectory frames, observables, checkpoints and status, each on its own
schedule (observables follow the frames unless output.observables sets a schedule of its own).
A stop request (signal, wall-time budget) writes a checkpoint at the next step boundary.
"""

from __future__ import annotations

import math
import time as wallclock
from dataclasses import dataclass, field

from .errors import NumericalError

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
    def from_config(cls, schedule, dt: float) -> StepSchedule:
        steps = schedule.every_steps
        if schedule.every_time is not None:
            by_time = max(1, round(schedule.every_time / dt))
            steps = by_time if steps is None else min(steps, by_time)
        wall = schedule.every_wall_minutes * 60.0 if schedule.every_wall_minutes else None
        return cls(every_steps=steps, wall_seconds=wall)

    def due(self, step: int, now: float) -> bool:
        if self.every_steps is not None and step % self.every_steps == 0:
            return True
        return self.wall_seconds is not None and now - self.last_wall >= self.wall_seconds

    def done(self, now: float) -> None:
        self.last_wall = now


class StopFlag:
    """Set from a signal handler or the wall-time budget; read once per step."""

    def __init__(self):
        self.reason: str | None = None
        # a second SIGINT: stop at once, with no final checkpoint (its KeyboardInterrupt is
        # raised where it lands, and raised again at the next step if Python dropped it there)
        self.interrupted = False

    def request(self, reason: str) -> None:
        if self.reason is None:
            self.reason = reason


def end_step_for(duration: float, dt: float) -> int:
    # the run reaches at least `duration`; the tiny tolerance absorbs round-off in duration/dt
    return max(0, math.ceil(duration / dt - 1e-9))


def advance(scene, steps: int) -> bool:
    """Advance the scene by `steps` steps with no output (library use and tests), or until the
    last stage ends. Returns True if a stage ended on the last step taken."""
    state = scene.state
    motion, neighbors, kicker = scene.motion, scene.neighbors, scene.kicker
    forces, after_step = scene.force_modules, scene.after_step_modules
    walls = [] if scene.wall_motion is None else [scene.wall_motion]
    stages = scene.stages
    finishers = scene.finish_modules
    clock = state.clock
    ended = False
    for _ in range(steps):
        if scene.finished:
            break
        for module in walls:
            module.kick_drift(state)
        motion.kick_drift(state)
        neighbors.prepare(state)
        for module in forces:
            module.forces(state)
        for module in walls:
            module.kick(state)
        kicker.kick(state)
        for module in finishers:
            module.finish_step(state)
        clock.step += 1
        for module in after_step:
            module.after_step(state)
        ended = stages is not None and stages.after_step(state)
    return ended


def check_stable(scene) -> None:
    """Raise NumericalError naming step, time and particle if the state has gone bad."""
    clock = scene.state.clock
    if scene.fluid is not None:
        problem = scene.fluid.first_unstable(scene.state)
        if problem is not None:
            raise NumericalError(
                f"numerical failure at step {clock.step} (t = {clock.time:.6g} s) in the fluid: {problem}. "
                "The newest checkpoint before this step is intact; a smaller dt or a finer coupling "
                "interval may help."
            )
    i, reason = scene.motion.first_unstable(scene.state)
    if i >= 0:
        p = scene.state.particles
        raise NumericalError(
            f"numerical failure at step {clock.step} (t = {clock.time:.6g} s): particle {i} at "
            f"{tuple(float(x) for x in p.pos[i])} m with velocity {tuple(float(x) for x in p.vel[i])} "
            f"m/s: {REASONS[reason][0]}. The newest checkpoint before this step is intact; "
            f"{REASONS[reason][1]}."
        )


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
        dt = scene.state.clock.dt
        out_cfg = scene.case.output
        self.frames = StepSchedule.from_config(out_cfg.frames, dt)
        self.checkpoints = StepSchedule.from_config(out_cfg.checkpoints, dt)
        observed = out_cfg.observables
        self.observations = None if observed.follows_frames else StepSchedule.from_config(observed, dt)
        self.status = StepSchedule(wall_seconds=progress.interval)
        self.check_every = scene.case.simulation.blowup_check_every

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
            stage_ended = advance(scene, 1)
            step = clock.step
            if self.progress.rate_start is None:
                self.progress.first_step_done(step)
            if stage_ended:
                self._stage_ended(scene)
            if step % self.check_every == 0:
                check_stable(scene)
            now = wallclock.monotonic()
            if self.frames.due(step, now):
                check_stable(scene)  # no frame with NaNs reaches the trajectory
                self.output.frame(scene)
                self.frames.done(now)
            if self.observations is not None and self.observations.due(step, now):
                self.output.observe(scene)
                self.observations.done(now)
            if self.checkpoints.due(step, now) and step < self.end_step:
                check_stable(scene)
                self.output.checkpoint(scene)
                self.checkpoints.done(now)
            if self.status.due(step, now):
                self.progress.update(scene, now - started)
                self.status.done(now)
        if self.stop.interrupted:
            raise KeyboardInterrupt
        check_stable(scene)
        self.output.frame(scene)
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
            log.info(
                "stage %r ended at step %d (t = %.6g s); now: %s", ended, clock.step, clock.time, stages.name
            )
        check_stable(scene)
        self.output.frame(scene)
        self.output.checkpoint(scene)
