"""Progress on stderr: a tqdm bar on a terminal, a periodic one-line status otherwise
(batch logs), and status.json in the run directory either way."""

from __future__ import annotations

import sys
import time

from tqdm import tqdm

from ..compile_lock import seconds_compiling


class Progress:
    def __init__(
        self,
        rundir,
        end_step: int,
        start_step: int,
        dt: float,
        n_particles: int,
        status_every: float,
        stream=None,
        enabled: bool = True,
        compiling=seconds_compiling,
    ):
        self.rundir = rundir
        self.end_step = end_step
        self.dt = dt
        self.n = n_particles
        self.stream = stream if stream is not None else sys.stderr
        self.bar = None
        self.enabled = enabled
        self.status_every = status_every
        self.last_status = float("-inf")
        # (step, monotonic time [s], seconds compiling then) after the first step
        self.rate_start: tuple[int, float, float] | None = None
        # the process's seconds spent compiling kernels so far (compile_lock.py), which the rate
        # leaves out: a fluid's kernels compile at its first step, hundreds of steps in
        self.compiling = compiling
        self.compiled_before = compiling()
        if enabled and self.stream.isatty():
            self.bar = tqdm(
                total=end_step,
                initial=start_step,
                file=self.stream,
                unit="step",
                dynamic_ncols=True,
                mininterval=0.5,
            )

    def first_step_done(self, step: int) -> None:
        """The rate counts from here: the first step compiles the step's kernels (seconds to
        minutes on a machine's first run), which would make the first ETAs days long."""
        self.rate_start = (step, time.monotonic(), self.compiling())

    def rate(self, step: int) -> float:
        """Steps per second [1/s] from the end of the first step to now, the seconds spent
        compiling kernels since then left out."""
        if self.rate_start is None:
            return 0.0
        first, then, compiled = self.rate_start
        steps = step - first
        seconds = time.monotonic() - then - (self.compiling() - compiled)
        return steps / seconds if steps > 0 and seconds > 0 else 0.0

    def info(self, scene, elapsed: float, state: str = "running") -> dict:
        clock = scene.state.clock
        rate = self.rate(clock.step)
        if state == "done":  # a staged run may end before its duration: its true end
            self.end_step = clock.step
        remaining = self.end_step - clock.step
        return {
            "state": state,
            "step": clock.step,
            "end_step": self.end_step,
            "time": clock.time,
            "end_time": self.end_step * self.dt,
            "dt": self.dt,
            "particles": self.n,
            "steps_per_second": rate,
            "particle_steps_per_second": rate * self.n,
            "elapsed_seconds": elapsed,
            "compiling_seconds": self.compiling_seconds(),
            "eta_seconds": remaining / rate if rate > 0 else None,
        }

    def compiling_seconds(self) -> float:
        """Seconds spent compiling kernels since this run's loop was set up."""
        return self.compiling() - self.compiled_before

    @property
    def interval(self) -> float:
        """How often the loop should call update() [s of wall time]."""
        return min(0.5, self.status_every) if self.bar is not None else self.status_every

    def update(self, scene, elapsed: float, state: str = "running") -> None:
        info = self.info(scene, elapsed, state)
        due = state != "running" or elapsed - self.last_status >= self.status_every
        if due:
            self.rundir.write_status(info)
            self.last_status = elapsed
        if not self.enabled:
            return
        if self.bar is not None:
            self.bar.total = self.end_step
            self.bar.n = info["step"]
            self.bar.set_postfix_str(
                f"t={info['time']:.4g}/{info['end_time']:.4g} s, {self._rate_text(info)}"
            )
            self.bar.refresh()
        elif due:
            eta = info["eta_seconds"]
            eta_text = f"{eta:.0f} s" if eta is not None else "?"
            print(
                f"[sphere] step {info['step']}/{self.end_step}  t = {info['time']:.6g} s  "
                f"{self._rate_text(info)}  ETA {eta_text}",
                file=self.stream,
                flush=True,
            )

    def _rate_text(self, info: dict) -> str:
        """Particle-steps per second, or steps per second in a scene without particles."""
        if self.n == 0:
            return f"{info['steps_per_second']:.3g} steps/s"
        return f"{info['particle_steps_per_second'] / 1e6:.2f} M particle-steps/s"

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()
