"""The run directory: case copy, trajectory + XDMF, checkpoints, status.json and run.log.

RUN_DIR/case.toml          the case as given (edit non-physics keys here before `resume`)
RUN_DIR/trajectory.h5      frames and observables (H5MD)
RUN_DIR/trajectory.xmf     ParaView sidecar
RUN_DIR/checkpoints/       ckpt-<step>.h5, newest K kept
RUN_DIR/status.json        progress for batch monitoring, rewritten atomically
RUN_DIR/run.log            what happened, appended by every run and resume
"""

from __future__ import annotations

import json
import logging
import shutil
from datetime import UTC, datetime
from pathlib import Path

from ..errors import OutputError, UsageError
from ..physics.fluid import MOVING_GRID_SPACING
from .atomic import write_text_atomic
from .checkpoint import remove_stale_temporaries, write_checkpoint
from .trajectory import Trajectory, is_grid_field
from .xdmf import write_xdmf

MARKERS = ("case.toml", "trajectory.h5", "checkpoints", "status.json")


class RunDirectory:
    def __init__(self, path: Path):
        self.path = Path(path)
        self.case = self.path / "case.toml"
        self.trajectory_path = self.path / "trajectory.h5"
        self.xdmf = self.path / "trajectory.xmf"
        self.checkpoints = self.path / "checkpoints"
        self.status_path = self.path / "status.json"
        self.log_path = self.path / "run.log"

    def is_run(self) -> bool:
        return self.case.is_file()

    def check_new(self, overwrite: bool) -> None:
        """Refuse, before any work, to clobber an existing run unless told to."""
        p = self.path
        if p.exists() and not p.is_dir():
            raise OutputError(f"{p}: exists and is not a directory")
        if p.is_dir() and any(p.iterdir()):
            if not overwrite:
                raise UsageError(
                    f"{p}: the run directory exists and is not empty; choose another with -o, "
                    "continue it with `sphere resume`, or pass --overwrite to replace it"
                )
            if not any((p / m).exists() for m in MARKERS):
                raise UsageError(f"{p}: --overwrite refused: this directory does not look like a sphere run")

    def prepare_new(self, overwrite: bool) -> None:
        p = self.path
        self.check_new(overwrite)
        if p.is_dir() and any(p.iterdir()):
            shutil.rmtree(p)
        try:
            p.mkdir(parents=True, exist_ok=True)
            self.checkpoints.mkdir(exist_ok=True)
            probe = p / ".write-test"
            probe.write_text("")
            probe.unlink()
        except OSError as exc:
            raise OutputError(f"{p}: cannot create the run directory ({exc})") from None
        remove_stale_temporaries(self.checkpoints)

    def logger(self) -> logging.Logger:
        log = logging.getLogger(f"sphere.run.{self.path.resolve()}")
        log.setLevel(logging.INFO)
        log.propagate = False
        if not log.handlers:
            try:
                handler = logging.FileHandler(self.log_path, encoding="utf-8")
            except OSError as exc:
                raise OutputError(f"{self.log_path}: cannot open the log ({exc})") from None
            handler.setFormatter(logging.Formatter("%(asctime)s %(levelname)s %(message)s"))
            log.addHandler(handler)
        return log

    def close_logger(self) -> None:
        log = logging.getLogger(f"sphere.run.{self.path.resolve()}")
        for handler in list(log.handlers):
            handler.close()
            log.removeHandler(handler)

    def write_status(self, info: dict) -> None:
        info = {**info, "updated": datetime.now(UTC).isoformat(timespec="seconds")}
        try:
            write_text_atomic(self.status_path, json.dumps(info, indent=2) + "\n")
        except OSError as exc:
            raise OutputError(f"{self.status_path}: cannot write status ({exc})") from None


class RunOutput:
    """Called by the loop on its schedules: frames, checkpoints."""

    def __init__(self, rundir: RunDirectory, scene, case_text: str, resolved: dict, physics_hash: str, log):
        self.rundir = rundir
        self.case_text = case_text
        self.resolved = resolved
        self.physics_hash = physics_hash
        self.log = log
        self.fields = list(scene.case.output.fields)
        self.trajectory = Trajectory(rundir.trajectory_path, self.fields)
        self.keep = scene.case.output.checkpoints.keep
        self.last_checkpoint: Path | None = None
        self.frame_times: list[float] = []
        self.observables_follow_frames = scene.case.output.observables.follows_frames

    def frame(self, scene) -> None:
        self.trajectory.append(scene)
        self._refresh_xdmf(scene)
        if self.observables_follow_frames:
            self.observe(scene)

    def first(self, scene) -> None:
        """The frame and observables of the starting state."""
        self.frame(scene)
        if not self.observables_follow_frames:
            self.observe(scene)

    def observe(self, scene) -> None:
        """One sample of the observables (on their schedule: computed only now)."""
        self.trajectory.append_observables(scene, scene.observer.sample())

    def _refresh_xdmf(self, scene) -> None:
        import h5py

        with h5py.File(self.rundir.trajectory_path, "r") as f:
            times = f["/particles/trajectory/position/time"][...].tolist()
            moving = f"/fluid/{MOVING_GRID_SPACING}/value"
            spacing = f[moving][...] if moving in f else None
        write_xdmf(
            self.rundir.xdmf,
            self.rundir.trajectory_path.name,
            times,
            scene.state.particles.count,
            self.fields,
            fluid=_xdmf_fluid(scene, spacing),
        )

    def checkpoint(self, scene) -> None:
        step = scene.state.clock.step
        if self.last_checkpoint is not None and self.last_checkpoint.name.endswith(f"{step:012d}.h5"):
            return
        self.last_checkpoint = write_checkpoint(
            self.rundir.checkpoints, scene, self.case_text, self.resolved, self.physics_hash, self.keep
        )
        self.log.info("checkpoint %s (t = %.6g s)", self.last_checkpoint.name, scene.state.clock.time)


def _xdmf_fluid(scene, spacing):
    """(grid, {field name: components}, spacing per frame or None) of the fluid's 3D fields, or None."""
    fluid = scene.fluid
    grid = fluid.grid() if fluid is not None else None
    if grid is None:
        return None
    fields = {}
    for name, (value, _unit) in fluid.output_fields(scene.state).items():
        if is_grid_field(value, grid):
            fields[name] = 1 if value.ndim == 3 else value.shape[3]
    return grid, fields, spacing
