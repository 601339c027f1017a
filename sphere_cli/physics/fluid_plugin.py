"""The fluid of a scene, whichever model the case picks, seen by the rest of the program.

A fluid model is one `FluidModule` subclass; the scene holds at most one. The builder imports
the model's module only when the case has a `[fluid]` section, so a dry scene imports, allocates,
compiles and writes nothing of any fluid. A model is a module of the step (physics/module.py):
it adds its forces after the contacts and walls, may take over the particles' second half kick
(implicit drag), and advances the fluid in after_step every `coupling_steps` steps.
"""

from __future__ import annotations

import copy
import importlib
import math
from dataclasses import dataclass, field

import numpy as np

from ..config.fluid_common import PressureBoundary
from ..config.load import warn
from ..errors import CaseError, MissingInputError
from ..runtime import grid_threads, threads_set_to
from .module import Module

# model tag -> "module:class", imported on demand
MODELS = {
    "navier-stokes": "sphere_cli.physics.fluid.navier_stokes:NavierStokes",
    "darcy": "sphere_cli.physics.fluid.darcy:Darcy",
    "vans1d": "sphere_cli.physics.fluid.vans1d:Vans1d",
}

# output field of a grid whose spacing changes in time (one that follows the top wall): the
# spacing (3,) [m] of each frame, which the XDMF sidecar and `inspect` read back
MOVING_GRID_SPACING = "grid_spacing"

# fluid steps a period of a modulated boundary pressure below which the run warns
RESOLVED_PERIOD = 20


# own_step_where of a fluid whose grid's step runs on the GPU (grid_on_gpu)
GRID_ON_GPU = "the grid's kernels and its pressure solve on the GPU, from the processor"


@dataclass
class GpuSteps:
    """A fluid's kernels on a GPU (physics/device_steps.py), each (CUDA kernel, threads, arguments
    as host arrays and numbers); the device holds one copy of each host array (the particles'
    own arrays are the device's), sent up again after each of the fluid's own steps."""

    forces: list[tuple]  # after the contacts and walls, adding its forces
    # in place of the particles' second half kick (none: the device's own); the last is the
    # kick, which also takes the device's largest displacement and zeroes it (cuda_dem.py kick)
    kick: list[tuple] = field(default_factory=list)
    # host arrays its kernels write, brought back with the state (and, without `coupling`,
    # before the fluid's own step, which may change them)
    written: tuple = ()
    # host arrays its stability test (first_unstable) reads of those, brought back for it
    checked: tuple = ()
    # at the end of a step after which the fluid takes its own step: kernels doing on the device
    # what that step needs of the particles, and the host arrays they write (brought back for
    # it); none: the particles and `written` come back instead. With them, `written` is the
    # device's alone: the fluid's step leaves it, and it is not sent up after that step.
    coupling: list[tuple] = field(default_factory=list)
    coupled: tuple = ()
    # host arrays the kernels write before they read them on the device (scratch, or results
    # that come back in `coupled`): sent up only when first allocated there
    scratch: tuple = ()


class FluidModule(Module):
    """Base class of the fluid models: the hooks of the step (physics/module.py) and these."""

    model = ""  # the [fluid] model tag, written to the trajectory
    name = "fluid"  # the checkpoint group of its prognostic state
    # forces and kick are the fluid's action on the particles (its own step is after_step): a
    # scene without particles leaves them out
    particle_hooks = ("forces", "kick")
    # the coupling when [fluid.coupling] gives neither steps nor interval: 1 step, or this [s]
    default_interval: float | None = None
    fluid_dt = math.nan  # the fluid step, coupling_steps x dt [s] (start_coupling)
    # split across MPI ranks (physics/rank_steps.py), the last step after which every rank took
    # its own step (step_on_rank), which the lead's after_step then leaves out
    stepped_on_ranks: int | None = None
    # the threads of its own step on its grid (runtime.grid_threads: by its cells, not by the
    # particles as the rest of the step); None: the run's
    step_threads: int | None = None

    def __init__(self, loaded, state):
        """Check the model against the rest of the case (raise loaded.error(...)) and allocate
        its arrays into a container set as state.fluid; reads the pressure series of its
        boundaries (a missing file exits 66, a malformed one 65, naming the key)."""
        self.loaded = loaded
        fluid = loaded.case.fluid
        for face in ("bottom", "top"):
            boundary = getattr(fluid, face, None)
            if isinstance(boundary, PressureBoundary) and boundary.series is not None:
                problem = boundary.read_series(loaded.base_dir)
                if problem is not None:
                    kind = MissingInputError if problem.startswith("file not found") else CaseError
                    raise kind(loaded.describe(("fluid", face, "series"), problem))

    def share_threads_by_cells(self, cells: int) -> None:
        """Its own grid step (on_its_threads) on a thread count of its cells' (a model with a
        grid calls this once the grid is made)."""
        self.step_threads = grid_threads(self.loaded.case, cells)

    def on_its_threads(self):
        """A context in which its parallel kernels run on its own step's threads."""
        return threads_set_to(self.step_threads)

    def grid_step_rehearsal(self) -> tuple | None:
        """(one kernel of its grid's own step, a module-level function, its arguments): the call
        takes one step of a copy of the grid alone, without the particles, so that the compile
        helper (sphere_cli/compile_ahead.py) compiles the grid step's kernels into the cache while
        the run compiles the rest; the kernel tells whether the cache holds them already. None:
        nothing to rehearse."""
        return None

    def start(self, state) -> None:
        """Called once state.clock.dt is known, for a new run and a resumed one alike: sets
        coupling_steps, the DEM steps between two fluid steps (start_coupling)."""
        self.start_coupling(state)

    def initialize(self, state) -> None:
        """New runs only, after start(): the initial fluid state."""

    def read_inputs(self) -> None:
        """What initialize() reads of the case's input (an initial field's file or expressions),
        read and checked without running a kernel: `sphere validate` calls it. Nothing by
        default."""

    # its action on the particles runs on a GPU (gpu_steps), the rest of it on the host between
    # coupling steps (physics/device_steps.py); a model whose action cannot is refused there
    on_gpu = False
    # its stability test (first_unstable) reads the particles' positions and velocities, which a
    # GPU then brings back for it
    stability_reads_particles = False
    # where its forces hook is one kernel called with force_arguments(state) and nothing else:
    # the compiled loops with that kernel in the place they leave for it (kernels/serial.py
    # variant of kernels/steps.py dem_steps and kernels/rank_messages.py rank_dem_steps), as
    # (steps, their one-thread twin, the ranks' steps, their twin); None: not so
    force_loops = None
    # a model with a compiled loop of its own (steps_kernel) that also runs on MPI ranks: that
    # loop's rank version and its one-thread twin (the Navier-Stokes drag's,
    # kernels/fluid/drag.py rank_drag_steps); None: its part's steps on a rank are taken one at
    # a time from Python
    rank_steps_kernels = None

    def gpu_steps(self, state) -> GpuSteps | None:
        """What runs on a GPU each step, for a model that is on_gpu, with its arguments as they are
        now (taken again after each of its own steps); imports the GPU's kernels, so only where a
        GPU is used."""
        return None

    # where its own step runs with the particles on a GPU (run.log), once grid_on_gpu has run
    own_step_where = "on the processor"

    def grid_on_gpu(self) -> None:
        """Where the particles' steps run on a GPU (physics/device_steps.py): what of the grid's
        own step runs there too (Navier-Stokes and Darcy: the step, physics/fluid/
        device_navier_stokes.py and device_pore_pressure.py; their own_step_where is then
        GRID_ON_GPU)."""

    def grid_device_bytes(self) -> int:
        """The bytes its grid's own step keeps on the GPU (after grid_on_gpu; none here)."""
        return 0

    def steps_taken(self, state, done: int) -> None:
        """After `done` steps of its compiled loop (`steps_kernel`, physics/compiled_steps.py),
        before the clock counts them: what the module reports of them (nothing here)."""

    def particle_arrays(self, state) -> dict | None:
        """{name: (holder, attribute)} of the arrays it keeps per particle, which travel with the
        particles between MPI ranks (physics/rank_steps.py); None: the model does not run split
        across ranks. A model that runs split also defines step_on_rank(state, whole, held),
        after_step on one rank's part: `state` the part's (its particles those the rank holds,
        `held` their global indices), `whole` what it takes of the whole scene (collectives:
        whole.near(needed, *arrays) the arrays of those of every rank's own particles that
        needed(own) marks for this rank, in global order; physics/rank_steps.py EveryRank);
        every rank takes the same step from them, bit for bit one rank's, so nothing is gathered
        at the lead nor sent back."""
        return None

    def split_grid(self, comm) -> None:
        """Split the fluid's own grid work across the MPI ranks of comm, the grid's
        communicator (ranks.py World.grid_comm), before each of its steps on ranks
        (step_on_rank), on every rank: a model whose step solves on its grid (Darcy,
        Navier-Stokes) splits its PoissonSolver, and its porosity sampling (and the
        Navier-Stokes momentum exchange and prediction) takes the solver's slabs; the 1D VANS
        column shares its layers out among the ranks of comm at each of its steps."""

    def plan_rank_steps(self, state) -> None:
        """Collective, on every MPI rank's part before its steps and after each list build
        (physics/rank_steps.py): what the module's messages of a step need until the next build
        (the Navier-Stokes drag's sums over each cell's particles); nothing here."""

    def ghost_arrays(self) -> tuple[str, ...]:
        """The names of particle_arrays, each (n, k), that its forces write from more than the
        particle and the fluid's own arrays (the other forces on it): a ghost's owner sends
        them with the force after each step's forces (physics/rank_steps.py)."""
        return ()

    def rank_copy(self, whole) -> FluidModule:
        """A copy of the module for one MPI rank's particles (physics/rank_steps.py): the
        holders of its particle_arrays its own, the fluid's own arrays shared. `whole`
        (EveryRank): what it takes of every rank's particles, in one rank's order, for a sum over
        particles inside its forces or kick."""
        return copy.copy(self)

    def dt_limit(self) -> tuple[float, str]:
        """The coupling's limit on dt (coupling_limit); a model adds its own."""
        return self.coupling_limit()

    # -- the coupling of [fluid.coupling], the same for every model --------------------------------

    def fluid_step_limit(self) -> tuple[float, str]:
        """The stability limit on the fluid step itself [s] and what sets it (inf: none)."""
        return math.inf, ""

    def wall_stiffness_limit(self, state) -> dict[int, tuple[float, str]]:
        """Stiffness [N/m] the fluid adds to each wall it pushes (wall index -> (stiffness,
        what it is)), which the wall's dt limit counts; none by default."""
        return {}

    def coupling_limit(self) -> tuple[float, str]:
        """The limit the coupling puts on dt [s]: the DEM sub-steps fluid.coupling.interval, or
        takes fluid.coupling.steps steps a fluid step (the fluid step's own limit divided by
        them). Checks, first, that a given interval is within the fluid step's limit."""
        interval, steps = self._coupling()
        limit, reason = self.fluid_step_limit()
        if interval is not None:
            if interval > limit:
                raise self.loaded.error(
                    ("fluid", "coupling", "interval"),
                    f"above the fluid's stability limit {limit:.4g} s ({reason}); "
                    f"use interval <= {limit:.4g} s",
                )
            return interval, "the DEM sub-steps the fluid step fluid.coupling.interval"
        if steps > 1:
            return limit / steps, f"{reason}, divided by fluid.coupling.steps = {steps}"
        return limit, reason

    def coupling_interval(self) -> float | None:
        """The coupling as a span of time [s] (fluid.coupling.interval, or the model's default
        where [fluid.coupling] gives neither); None when it is a number of steps."""
        return self._coupling()[0]

    def _coupling(self) -> tuple[float | None, int]:
        """(interval [s] or None, steps) of [fluid.coupling], the model's default where it gives
        neither."""
        coupling = self.loaded.case.fluid.coupling
        if coupling.interval is None and coupling.steps is None:
            return self.default_interval, 1
        return coupling.interval, coupling.steps or 1

    def start_coupling(self, state) -> None:
        """coupling_steps and the fluid step fluid_dt [s] once dt is known (the one rule for a
        span of time, Clock.steps_in, for an interval); a rounded interval above the fluid
        step's limit is refused."""
        interval, steps = self._coupling()
        clock = state.clock
        self.coupling_steps = clock.steps_in(interval) if interval is not None else steps
        self.fluid_dt = self.coupling_steps * clock.dt
        limit, reason = self.fluid_step_limit()
        if interval is not None and self.fluid_dt > limit:
            raise self.loaded.error(
                ("fluid", "coupling", "interval"),
                f"is {self.coupling_steps} DEM steps of dt = {clock.dt:.6g} s, a fluid step of "
                f"{self.fluid_dt:.6g} s, above the fluid's stability limit {limit:.4g} s ({reason}); "
                f"use interval <= {limit - clock.dt:.4g} s or a dt that divides it",
            )
        self._check_modulations()

    def _check_modulations(self) -> None:
        """A boundary pressure modulated faster than the fluid step can follow: refused below
        two fluid steps a period (sampled at the steps, the modulation would alias into a slower
        one, a plausible wrong answer), warned below RESOLVED_PERIOD steps (backward Euler and
        the projection shift its phase and damp it by about omega dt / 2)."""
        fluid = self.loaded.case.fluid
        for face in ("bottom", "top"):
            boundary = getattr(fluid, face, None)
            if not isinstance(boundary, PressureBoundary) or boundary.amplitude == 0.0:
                continue
            steps = boundary.period / self.fluid_dt
            what = (
                f"{steps:.3g} fluid steps of {self.fluid_dt:.4g} s a period (dt x "
                f"{self.coupling_steps} DEM steps a fluid step)"
            )
            if steps < 2.0:
                raise self.loaded.error(
                    ("fluid", face, "period"),
                    f"{what}: the modulation is faster than the fluid step can sample (2 steps a "
                    f"period at least) and would alias into a slower one; use a period >= "
                    f"{2.0 * self.fluid_dt:.4g} s or a fluid step <= {boundary.period / 2.0:.4g} s",
                )
            if steps < RESOLVED_PERIOD:
                warn(
                    self.loaded.describe(
                        ("fluid", face, "period"),
                        f"{what}: below {RESOLVED_PERIOD} steps a period the modulation's amplitude "
                        f"and phase inside the domain carry errors of about omega dt / 2 = "
                        f"{math.pi / steps:.2g}; a smaller dt or fluid step resolves it",
                    )
                )

    def first_unstable(self, state) -> str | None:
        """A message naming the cell (or level), the quantity and its value when the fluid state
        has gone bad; None when it is fine. On a GPU (physics/device_steps.py) it is asked with
        the particles' arrays on the host stale but for those its force writes: it reads the
        fluid's own fields and those."""
        return None

    def output_fields(self, state) -> dict[str, tuple[np.ndarray, str]]:
        """name -> (array, unit) written with every frame under /fluid/<name>. Fields on a 3D
        grid are cell-centred, shape (nx, ny, nz) or (nx, ny, nz, 3). A grid that moves adds
        its spacing (3,) [m] as MOVING_GRID_SPACING."""
        return {}

    def grid(self):
        """The FluidGrid (physics/fluid/grid.py) of 3D fields, for the XDMF sidecar; None for
        a model without a 3D grid."""
        return None

    def summary(self) -> dict[str, str]:
        """A few facts for run.log and `sphere inspect` (model, grid, solver)."""
        return {}


def build_fluid(loaded, state) -> FluidModule | None:
    """The fluid module of the case, or None for a dry scene (nothing fluid is imported)."""
    spec = loaded.case.fluid
    if spec is None:
        return None
    module_name, class_name = MODELS[spec.model].split(":")
    try:
        module = importlib.import_module(module_name)
    except ModuleNotFoundError as exc:
        if exc.name != module_name:
            raise
        raise loaded.error(
            ("fluid", "model"), f'the fluid model "{spec.model}" is not available in this version'
        ) from None
    return getattr(module, class_name)(loaded, state)
