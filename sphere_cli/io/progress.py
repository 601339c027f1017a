"""Progress on stderr: a tqdm bar on a terminal, a periodic one-line status otherwise
(batch logs), and status.json in the run directory either way."""

from __future__ import annotations

import sys
import threading
import time

from tqdm import tqdm

from .. import compile_lock

# a compile inside the loop that lasts longer than this is announced [s] (a fluid's kernels
# compile at its first fluid step, half a minute on a first run, with nothing printed else)
COMPILE_NOTICE_SECONDS = 2.0


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
        compiling=compile_lock.seconds_compiling,
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
        self.notice_seconds = COMPILE_NOTICE_SECONDS
        self._notice: threading.Timer | None = None
        self._noticed = False  # once a run
        if enabled:
            compile_lock.watchers.append(self._compile_watch)
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

    def _compile_watch(self, began: bool) -> None:
        """compile_lock's watcher: a compile in the loop (after the first step: the build's have
        their own line) that lasts notice_seconds gets a line, once a run."""
        if not began:
            if self._notice is not None:
                self._notice.cancel()
                self._notice = None
            return
        if self.rate_start is None or self._noticed:
            return
        self._notice = threading.Timer(self.notice_seconds, self._announce_compile)
        self._notice.daemon = True
        self._notice.start()

    def _announce_compile(self) -> None:
        self._noticed = True
        text = "compiling kernels (a first run of this kind of case; cached for later runs) ..."
        if self.bar is not None:
            self.bar.set_postfix_str(text)
            self.bar.refresh()
        else:
            print(f"[sphere] {text}", file=self.stream, flush=True)

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
        if self._compile_watch in compile_lock.watchers:
            compile_lock.watchers.remove(self._compile_watch)
        self._compile_watch(False)
        if self.bar is not None:
            self.bar.close()
