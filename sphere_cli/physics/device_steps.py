"""The DEM steps on a CUDA GPU (`[simulation] device = "cuda"`): the kernels of
kernels/cuda_dem.py in the order of the step (kick-drift, the neighbour list rebuilt on the
device when some particle has moved half the skin, the pair contacts, the kick), with the state
kept on the device across calls of simulation.advance and copied back only when the host reads it
(`to_host`: at the end of a library call of advance, and before the run loop's frames,
observables, checkpoints and stability checks), which then read the host arrays as on the CPU.

It takes the place of physics/compiled_steps.py for the scenes it covers: particles, their pair
contacts (both laws, friction, rolling, several materials), gravity, plane walls (fixed, moving at
a set velocity or keeping a stress, with spheres glued to them) and periodic boundaries. The
walls' own steps run on one GPU thread each half step (a few walls); the particles' forces on
them are summed exactly as on the CPU (kernels/exact_sum.py), one thread a particle, by integer
atomics, which give the same sum in any order.
Stages run on the host, as on the CPU: what their test reads comes back before each step where
a stage may end (Stages.after_due), the whole state where one does end (Stages.ends_at), and it
goes up again when the next has begun (its walls' modes, its friction, an approach). So does a
fluid whose action on the particles runs on the GPU (FluidModule.on_gpu, gpu_steps: the 1D VANS
profile's force, kernels/fluid/cuda_profile_forces.py; Darcy's and its push on a wall,
kernels/fluid/cuda_darcy.py; the Navier-Stokes drag and its kick, kernels/fluid/cuda_drag.py):
its own step is called from the host at its coupling steps (the Navier-Stokes and Darcy grids'
kernels and pressure solve then run on the device: FluidModule.grid_on_gpu), from the particles
and what its kernels wrote brought back, or from what its coupling kernels made on the device (the
Navier-Stokes porosity and momentum exchange, the Darcy porosity and mean particle velocity,
kernels/fluid/cuda_porosity.py, on a grid that keeps its cells), and its arrays go up again
after each. The energy budget books each particle's share of a step on the
device (kernels/observe/cuda_energy_budget.py), its copies of the half-step velocities and of the
last wall springs taken before the contacts, the last pair springs those of the spare spring
buffer after the contacts. A case with anything else in its step is refused with the modules
named; so is a fluid without particles, and a machine without a usable GPU. Results agree
with the CPU to round-off: the GPU's compiler fuses a multiply and an add into one rounding
(FMA) where the CPU rounds twice (docs/user-guide.md, "The GPU").

The host's neighbour list is a half list with packed springs (kernels/neighbors.py); the device
holds full rows with the springs at the owner's slot (kernels/cuda_dem.py). The two are
converted at the upload and the download, so a checkpoint written from a GPU run resumes on
the CPU and the other way round.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np
from numba import config

from ..errors import CaseError
from ..kernels.exact_sum import WORDS
from ..kernels.neighbors import count_half_rows, fill_half_rows, row_starts
from ..state import State
from .compiled_steps import plain_step
from .neighbors import INITIAL_CAPACITY, SPRING_ROOM, NeighborSearch, listed_slots

# threads per block: any size gives the same results (each particle's sums are its own item's)
THREADS = 128
# (blocks, threads) of every launch under Numba's CUDA simulator, where each CUDA thread is a
# Python thread started anew at each launch: one thread striding over the items (40 particles,
# a light kernel: 1.1 ms a launch against 6.6 ms with 40 threads, and slower still beside
# other processes); tests change it to check that results do not depend on the launch
SIMULATOR_LAUNCH = (1, 1)
# the modules the GPU step runs (the Observer, "observables" or "" where it has no state, only
# measures, from the host arrays)
SUPPORTED = (
    "particles", "neighbors", "contact", "walls", "wall_motion", "stages", "observables", "energy_budget", "",
)  # fmt: skip
# the walls' arrays that moving walls change on the device, and those they only read
MOVED = ("coord", "vel", "vel_pred", "acc", "shift", "force", "area", "fluid_force")
DRIVING = ("mode", "control")
# row and cell slots added on growth, beyond the longest seen
ROW_HEADROOM = 4
CELL_SLOTS = 8


def _no_gpu(why: str) -> CaseError:
    return CaseError(
        f'simulation.device = "cuda": no GPU can be used here ({why}). The GPU needs an NVIDIA '
        "GPU, its driver and the CUDA extra (pip install 'sphere-cli[cuda]'); "
        'device = "cpu" (the default) runs the same case on the processor.'
    )


def _cuda():
    """(numba.cuda, kernels/cuda_dem.py), or a CaseError naming the key when no GPU can be used
    here: none found, or one that cannot compile and run a kernel (a driver without the compiler
    the CUDA extra brings), tried before the run directory is written."""
    try:
        from numba import cuda

        usable = cuda.is_available()
    except Exception as exc:  # a broken CUDA installation: its own message
        raise _no_gpu(f"{type(exc).__name__}: {exc}") from None
    if not usable:
        raise _no_gpu("numba.cuda finds no CUDA GPU with a working driver")
    try:
        from ..kernels import cuda_dem

        probe = cuda.to_device(np.ones(1, dtype=np.int32))
        cuda_dem.clear[1, 1](probe)
        if probe.copy_to_host()[0] != 0:
            raise RuntimeError("a kernel ran without effect")
    except Exception as exc:
        raise _no_gpu(f"a first kernel failed: {type(exc).__name__}: {exc}") from None
    return cuda, cuda_dem


def launch_shape(items: int) -> tuple[int, int]:
    """(blocks, threads) of a launch over `items`: a thread an item, in blocks of THREADS (one
    block of `items` threads where that is fewer), or SIMULATOR_LAUNCH under the simulator."""
    if config.ENABLE_CUDASIM:
        return SIMULATOR_LAUNCH
    threads = min(THREADS, max(items, 1))
    return math.ceil(max(items, 1) / threads), threads


def search_grid_problem(neighbors: NeighborSearch, count: int) -> str | None:
    """Why the GPU cannot search this box for its `count` particles (a box of more cells than the
    CPU stores whole: it keeps the occupied ones, the GPU's search stores every cell), or None.
    Asked by the build and by `sphere validate` (scene/builder.py check_build)."""
    if neighbors.dense:
        return None
    return (
        f'simulation.device = "cuda": the box holds {int(np.prod(neighbors.ncell))} search cells for '
        f"{count} particles; the GPU's search stores every cell. Make the domain smaller around the "
        'particles, or use device = "cpu".'
    )


def on_gpu_or_error(work):
    """Run `work` (host calls into numba.cuda); a CUDA error (out of memory above all) becomes a
    CaseError naming the key instead of a traceback."""
    try:
        return work()
    except Exception as exc:
        if not type(exc).__module__.startswith(("numba.cuda", "numba_cuda", "cuda")):
            raise
        raise CaseError(
            f'simulation.device = "cuda": the GPU failed: {type(exc).__name__}: {exc} (out of memory: '
            'a GPU with more memory, fewer particles, or device = "cpu")'
        ) from None


def _gpu_name(cuda) -> str:
    if config.ENABLE_CUDASIM:
        return "Numba's CUDA simulator (NUMBA_ENABLE_CUDASIM=1)"
    name = cuda.get_current_device().name
    return name.decode() if isinstance(name, bytes) else str(name)


def _key(a: np.ndarray) -> tuple:
    """What tells a host array apart: its memory and type (views of one contiguous array, such as
    a grid's field and its flat form, share it)."""
    return a.__array_interface__["data"][0], a.nbytes, a.dtype.str


def _to_host(pairs: tuple) -> None:
    """Each (host array, device array) copied back."""
    for host, device in pairs:
        device.copy_to_host(host)


def _fluid_on_gpu(scene):
    """The scene's fluid if its force runs on the GPU (FluidModule.on_gpu), else None."""
    fluid = scene.fluid
    return fluid if fluid is not None and fluid.on_gpu else None


@dataclass
class Rows:
    """A neighbour list on the device: full rows and each pair's slot in its partner's row."""

    nbr: object
    count: object
    mate: object


class DeviceSteps:
    # takes any number of whole steps, list rebuilds included (simulation.advance)
    whole_steps = True

    def __init__(self, scene, cuda, kernels):
        self.cuda = cuda
        self.k = kernels  # kernels/cuda_dem.py, imported only where a GPU is used
        self.search: NeighborSearch = scene.neighbors
        self.contact = scene.contact
        self.springs = self.search.springs
        self.walls = scene.walls  # plane walls, or None
        self.moving = scene.wall_motion is not None  # some wall moves (WallMotion's steps)
        self.stages = scene.stages  # their after_step reads and changes the host's state, or None
        self.budget = scene.budget  # the energy budget (its shares booked on the device), or None
        self.fluid = _fluid_on_gpu(scene)  # a fluid: its own step on the host, or None
        if self.fluid is not None:
            self.fluid.grid_on_gpu()  # but for what of it the GPU takes
        self.fluid_due = None  # the step at whose end the fluid takes its step on the host
        self.fluid_steps = None  # its GpuSteps with the arguments on the device (_fluid_arguments)
        # (host array, device array) of those its kernels write, its stability test reads of
        # those, and the kernels at the end of a step before its own step write
        self.fluid_written = self.fluid_checked = self.fluid_coupled = ()
        self.mirrors = {}  # the device's copy of each host array of the fluid's, by _key
        self.rows = self.spare = None
        self.on_device_at = None  # the host step the device state is for (None: upload)
        self.builds = 0
        self.device_name = _gpu_name(cuda)  # for run.log
        self.timings = None  # {kernel: seconds} while profiling (_launch)
        self.host_stale = False  # steps taken on the device since the last download

    @classmethod
    def of(cls, scene) -> DeviceSteps:
        """The GPU steps of a scene, or a CaseError saying what the GPU does not run yet."""
        fluid = _fluid_on_gpu(scene)
        extra = [m.name for m in scene.modules if m.name not in SUPPORTED and m is not fluid]
        if scene.state.particles.count == 0:
            extra.append("no particles (a fluid-only case)")
        # any other module that acts between steps (the named ones are reported above; the
        # stages act on the host's state, which comes back for them)
        between = [m for m, _ in scene.step.after_step if m.name in SUPPORTED and m is not scene.stages]
        extra += [f"{m.name or type(m).__name__} after its steps" for m in between]
        if extra or scene.neighbors is None or not plain_step(scene, budget=True):
            raise CaseError(
                f'simulation.device = "cuda" runs the particles, their pair contacts, gravity, plane '
                "walls, stages, the 1D VANS, Darcy and Navier-Stokes fluids and periodic boundaries; this "
                "case also has: "
                f'{", ".join(extra) or "other step hooks"}. Run it with device = "cpu" (the default).'
            )
        problem = search_grid_problem(scene.neighbors, scene.state.particles.count)
        if problem is not None:
            raise CaseError(problem)
        return cls(scene, *_cuda())

    # --- host <-> device ------------------------------------------------------------------

    def _launch(self, kernel, size: int, *args) -> None:
        """`kernel` over `size` items (launch_shape)."""
        launch = kernel[launch_shape(size)]
        if self.timings is None:
            launch(*args)
            return
        # profiling (sphere bench gpu): each kernel waited for, its time added to its name's
        self.cuda.synchronize()
        started = time.perf_counter()
        launch(*args)
        self.cuda.synchronize()
        name = kernel.py_func.__name__
        self.timings[name] = self.timings.get(name, 0.0) + time.perf_counter() - started

    def device_bytes(self) -> int:
        """The bytes this keeps on the device, a fluid's arrays included (sphere bench gpu's memory
        per particle)."""
        arrays = [
            *self.d.values(),
            self.cell_of,
            self.cell_count,
            self.cell_members,
            self.hist,
            self.hist_next,
            *self.mirrors.values(),
        ]
        for rows in (self.rows, self.spare):
            arrays += [rows.nbr, rows.count, rows.mate]
        grid = 0 if self.fluid is None else self.fluid.grid_device_bytes()
        return sum(a.nbytes for a in arrays) + grid

    def upload(self, state: State) -> None:
        """The particles, the box, the contact table and the host's list with its springs."""
        to = self.cuda.to_device
        p, box, nl = state.particles, state.box, state.neighbors
        self.d = {
            name: to(getattr(p, name))
            for name in (
                "pos", "vel", "angvel", "force", "torque", "vel_pred", "angvel_pred", "radius",
                "inv_mass", "inv_inertia", "mass", "material",
            )
        }  # fmt: skip
        self.d.update(
            lower=to(box.lower),
            upper=to(box.upper),
            length=to(box.length),
            periodic=to(box.periodic),
            body_acc=to(box.body_acc),
            table=to(self.contact.table),
            ref_pos=to(nl.ref_pos),
            cell_size=to(self.search.cell_size),
            ncell=to(self.search.ncell),
            worst=to(np.zeros(1)),
            longest=to(np.zeros(2, dtype=np.int32)),
        )
        cells = int(np.prod(self.search.ncell))
        self.cell_of = self.cuda.device_array(p.count, dtype=np.int64)
        self.cell_count = self.cuda.device_array(cells, dtype=np.int32)
        self.cell_members = self.cuda.device_array((cells, CELL_SLOTS), dtype=np.int32)
        if self.walls is not None:
            w = state.walls
            self.wall_springs = w.hist.shape[0] > 0  # none without friction
            self.d.update(
                wall_axis=to(w.axis),
                wall_sign=to(w.sign),
                wall_coord=to(w.coord),
                wall_vel=to(w.vel),
                wall_vel_pred=to(w.vel_pred),
                wall_table=to(w.table),
                wall_hist=to(w.hist if self.wall_springs else np.zeros((1, 1, 3))),
                inertia=to(p.inertia),
                record=to(w.record),
                # each particle's force from the walls marked in record (written every step)
                pforce=to(np.zeros((p.count if self.moving else 1, len(w.faces), 3))),
            )
            if self.moving:
                self.d.update(
                    {f"wall_{name}": to(getattr(w, name)) for name in MOVED[3:] + DRIVING},
                    attached=to(w.attached),
                    attached_wall=to(w.attached_wall),
                    sums=to(np.zeros((len(w.faces), 3, WORDS), dtype=np.int64)),
                )
        if self.budget is not None:
            self._budget_arrays(state)
        if self.fluid is not None:
            self._fluid_arguments(state, everything=True)
        self.rows, self.hist = self._full_rows(nl, p.count)
        self.spare = self._allocate(p.count, self.rows.nbr.shape[1])
        self.hist_next = self._springs(p.count, self.rows.nbr.shape[1])
        self.on_device_at = state.clock.step

    def _budget_arrays(self, state: State) -> None:
        """The energy budget's shares, and its copies of the step's half-step velocities and
        last wall springs (taken before each step's contacts), on the device; empty walls
        without walls (kernels/observe/cuda_energy_budget.py)."""
        from ..kernels.observe.cuda_energy_budget import book

        self.book = book  # imported only where the budget runs on a GPU
        to, empty = self.cuda.to_device, self.cuda.device_array
        n = state.particles.count
        d = self.d
        d.update(
            booked=to(self.budget.booked),
            vel_half=empty((n, 3)),
            angvel_half=empty((n, 3)),
            budget_scratch=empty((n, 2, 3)),
            no_spring=to(np.zeros(3)),
        )
        if self.walls is not None:
            d.update(wall_vel_half=empty(d["wall_vel"].shape), wall_hist_last=empty(d["wall_hist"].shape))
            return
        none = np.zeros((0, 3))
        d.update(
            inertia=to(state.particles.inertia),
            wall_axis=to(np.zeros(0, dtype=np.int64)),
            wall_sign=to(np.zeros(0)),
            wall_coord=to(np.zeros(0)),
            wall_vel=to(none),
            wall_vel_pred=to(none),
            wall_vel_half=to(none),
            wall_table=to(np.zeros((0, 1, 6))),
            wall_hist_last=to(np.zeros((n, 0, 3))),
        )

    def _fluid_arguments(self, state: State, everything: bool = False) -> None:
        """The fluid's kernels with their arguments on the device (its gpu_steps): the particles'
        own arrays, one device copy of each of its host arrays (the views of one array share it),
        its numbers as they are now. Sent again after each fluid step, into the arrays already
        on the device (none allocated then), but for the kernels' scratch and those that are the
        device's alone (GpuSteps.written with a coupling on the device) unless `everything` (an
        upload)."""
        own = {_key(a): name for name, a in vars(state.particles).items() if name in self.d}
        if self.walls is not None:  # the walls' arrays on the device (a Darcy fluid's push)
            walls = vars(state.walls).items()
            own.update({_key(a): f"wall_{name}" for name, a in walls if f"wall_{name}" in self.d})
        host = self.fluid.gpu_steps(state)
        kept = {_key(a) for a in (*host.scratch, *(() if everything or not host.coupling else host.written))}
        mirrors = {}

        def on_device(a):
            if not isinstance(a, np.ndarray):
                return a
            if not a.flags.c_contiguous:  # its key would not tell it from another view
                raise ValueError(f"{type(self.fluid).__name__}.gpu_steps: an argument is not C-contiguous")
            key = _key(a)
            if key in own:
                return self.d[own[key]]
            if key not in mirrors:
                if key not in self.mirrors:
                    mirrors[key] = self.cuda.to_device(a)
                else:
                    mirrors[key] = self.mirrors[key]
                    if key not in kept:
                        mirrors[key].copy_to_device(a.reshape(mirrors[key].shape))
            device = mirrors[key]
            return device if device.shape == a.shape else device.reshape(a.shape)

        def launches(steps):
            return [(kernel, size, tuple(on_device(a) for a in args)) for kernel, size, args in steps]

        def pairs(arrays):
            return tuple((a, on_device(a)) for a in arrays)

        self.fluid_steps = type(host)(
            launches(host.forces), launches(host.kick), coupling=launches(host.coupling)
        )
        self.fluid_written, self.fluid_checked = pairs(host.written), pairs(host.checked)
        self.fluid_coupled = pairs(host.coupled)
        self.mirrors = mirrors

    def _allocate(self, n: int, width: int) -> Rows:
        cuda = self.cuda
        return Rows(
            cuda.device_array((n, width), dtype=np.int32),
            cuda.device_array(n, dtype=np.int32),
            cuda.device_array((n, width), dtype=np.int32),
        )

    def _springs(self, n: int, width: int, host: np.ndarray | None = None):
        """A buffer of springs for rows of `width` slots (a placeholder without springs); left
        unset without `host`: every slot read is written first (by the forces or the carry)."""
        if not self.springs:
            return self.cuda.to_device(np.zeros((1, 1, 3)))
        return self.cuda.device_array((n, width, 3)) if host is None else self.cuda.to_device(host)

    def _full_rows(self, nl, n: int) -> tuple[Rows, object]:
        """The host's half rows as full rows on the device, and the springs, each at its owner's
        slot."""
        listed = listed_slots(nl.nbr, nl.nbr_count)
        owner = np.repeat(np.arange(n), listed.sum(axis=1))
        partner = nl.nbr[listed].astype(np.int64)
        rows = np.concatenate([owner, partner])
        cols = np.concatenate([partner, owner])
        order = np.lexsort((cols, rows))
        count = np.bincount(rows, minlength=n)
        first = np.concatenate([[0], np.cumsum(count)[:-1]])
        slot = np.empty(rows.size, dtype=np.int64)
        slot[order] = np.arange(rows.size) - np.repeat(first, count)
        width = int(count.max(initial=0)) + ROW_HEADROOM
        nbr = np.zeros((n, width), dtype=np.int32)
        nbr[rows, slot] = cols
        mate = np.zeros((n, width), dtype=np.int32)
        mate[rows, slot] = np.concatenate([slot[owner.size :], slot[: owner.size]])
        made = self._allocate(n, width)
        made.nbr.copy_to_device(nbr)
        made.count.copy_to_device(count.astype(np.int32))
        made.mate.copy_to_device(mate)
        hist = np.zeros((n, width, 3))
        if self.springs:
            hist[owner, slot[: owner.size]] = nl.hist[: owner.size]
        return made, self._springs(n, width, hist)

    def download(self, state: State) -> None:
        """The particles' arrays and the list (as half rows with packed springs) back into the
        host's arrays."""
        self._particles_to_host(state)
        self._rest_to_host(state)

    def _rest_to_host(self, state: State) -> None:
        """All but what _particles_to_host brings back."""
        p, nl = state.particles, state.neighbors
        for name in ("force", "torque", "vel_pred", "angvel_pred"):
            self.d[name].copy_to_host(getattr(p, name))
        self.d["ref_pos"].copy_to_host(nl.ref_pos)
        if self.walls is not None and self.wall_springs:
            # a new array: the wall module derives its mask of set springs again (physics/walls.py)
            state.walls.hist = self.d["wall_hist"].copy_to_host()
        if self.fluid is not None:
            self._fluid_outputs_to_host(self.fluid_written)
        if self.budget is not None:
            self.d["booked"].copy_to_host(self.budget.booked)
        nbr = self.rows.nbr.copy_to_host()
        count = self.rows.count.copy_to_host()
        n = count.size
        half = np.empty(n, dtype=np.int32)
        count_half_rows(nbr, count, half)
        width = max(nl.nbr.shape[1], int(half.max(initial=0)), INITIAL_CAPACITY)
        nl.nbr = np.zeros((n, width), dtype=np.int32)
        nl.nbr_count = half
        pairs = int(row_starts(nl.nbr_count, width, nl.start))
        full_hist = self.hist.copy_to_host() if self.springs else np.zeros((1, 1, 3))
        if self.springs:
            nl.hist = np.zeros((int(SPRING_ROOM * pairs) + 64, 3))
        fill_half_rows(nbr, count, full_hist, self.springs, nl.start, nl.nbr, nl.hist)
        nl.builds += self.builds
        self.builds = 0
        self.search._spare_like(nl)
        self.search._reverse(nl)

    # --- the step -------------------------------------------------------------------------

    def run(self, state: State, steps: int) -> tuple[int, bool]:
        """Take `steps` whole steps on the device; the host arrays are stale until to_host."""
        return on_gpu_or_error(lambda: self._run(state, steps))

    def to_host(self, state: State) -> None:
        """Bring the state back into the host's arrays, if steps were taken since."""
        if self.host_stale:
            on_gpu_or_error(lambda: self.download(state))
            self.host_stale = False

    def _particles_to_host(self, state: State) -> None:
        """What a fluid's own step reads of the particles and the walls (positions, velocities,
        spins; the walls' positions, which a grid may follow), without the list: the state on the
        device goes on as it is, and a later to_host brings the rest."""
        p = state.particles
        for name in ("pos", "vel", "angvel"):
            self.d[name].copy_to_host(getattr(p, name))
        self._moving_walls_to_host(state)

    def _moving_walls_to_host(self, state: State) -> None:
        """The arrays of the walls that moving walls change on the device."""
        if self.moving:
            for name in MOVED:
                self.d[f"wall_{name}"].copy_to_host(getattr(state.walls, name))

    def _fluid_outputs_to_host(self, pairs: tuple) -> None:
        """Those of the arrays the fluid's kernels write on the device (GpuSteps.written, or of
        those, checked) into the host's, unless the fluid's step on the host has made them since
        (at the step the device is at, where they came back for it)."""
        if self.fluid_steps.coupling or self.fluid_due != self.on_device_at:
            _to_host(pairs)

    def hand_over(self, state: State) -> None:
        """to_host, for a caller who may change the host's arrays before the next steps: those
        then start from the host's arrays again (an upload), changed or not."""
        self.to_host(state)
        self.on_device_at = None

    def known_stable(self, state: State) -> bool:
        """True if the state on the device has no particle gone bad (checked there, without
        bringing the state back) and a fluid's own test passes (on its host fields, which its
        step keeps current, and what its force wrote, brought back alone); False where the host
        must look (simulation.check_stable): something has gone bad, or the host's arrays are
        current anyway."""
        if not self.host_stale:
            return False
        return on_gpu_or_error(lambda: self._stable_on_device(state))

    def _stable_on_device(self, state: State) -> bool:
        k = self.k
        d, n = self.d, state.particles.count
        first = self.cuda.to_device(np.full(1, n, dtype=np.int64))
        self._launch(
            k.find_unstable, n, d["pos"], d["vel"], d["angvel"], d["radius"], d["lower"], d["upper"],
            d["periodic"], state.clock.dt, first,
        )  # fmt: skip
        if int(first.copy_to_host()[0]) != n:
            return False
        if self.fluid is not None:
            if self.fluid.stability_reads_particles:
                self._particles_to_host(state)
            self._fluid_outputs_to_host(self.fluid_checked)
            return self.fluid.first_unstable(state) is None
        return True

    def _run(self, state: State, steps: int) -> tuple[int, bool]:
        k = self.k
        # again from the host where it is ahead, or where a stage has just begun there
        stage_began = self.stages is not None and self.stages.ended_at == state.clock.step
        if self.on_device_at != state.clock.step or stage_began:
            self.upload(state)
        elif self.fluid_due == state.clock.step:  # the fluid's step on the host: its fields
            self._fluid_arguments(state)
        d, n = self.d, state.particles.count
        dt = state.clock.dt
        d["worst"].copy_to_device(np.zeros(1))  # then zeroed by each step's kick on the device
        moved2 = 0.0
        for taken in range(steps):
            if self.moving:
                self._launch(
                    k.wall_motion_drift, 1, d["wall_axis"], d["wall_sign"], d["wall_mode"], d["wall_control"],
                    d["wall_coord"], d["wall_vel"], d["wall_acc"], d["wall_vel_pred"], d["wall_shift"], dt,
                    d["attached"], d["attached_wall"], d["vel"],
                )  # fmt: skip
            self._launch(
                k.kick_drift, n, d["pos"], d["vel"], d["angvel"], d["force"], d["torque"], d["inv_mass"],
                d["inv_inertia"], d["lower"], d["length"], d["periodic"], dt, d["vel_pred"],
                d["angvel_pred"], d["ref_pos"], d["worst"],
            )  # fmt: skip
            moved2 = float(d["worst"].copy_to_host()[0])
            if moved2 > self.search.threshold2:
                self.rebuild(state)
                moved2 = 0.0  # as the host's rebuild leaves it
            rows = self.rows
            if self.budget is not None:  # what it books the step from (EnergyBudget.forces)
                for now in ("vel", "angvel", "wall_vel"):
                    d[f"{now}_half"].copy_to_device(d[now])
                if self.walls is not None and self.wall_springs:
                    d["wall_hist_last"].copy_to_device(d["wall_hist"])
            self._launch(
                k.pair_forces, n, d["pos"], d["vel"], d["angvel"], d["vel_pred"], d["angvel_pred"],
                d["radius"], d["inv_mass"], d["inv_inertia"], d["material"], d["mass"], d["body_acc"],
                rows.nbr, rows.count, rows.mate, self.hist, self.hist_next, self.springs, d["table"],
                self.contact.law_code, self.contact.rolling, d["length"], d["periodic"], dt, dt,
                d["force"], d["torque"],
            )  # fmt: skip
            self.hist, self.hist_next = self.hist_next, self.hist
            if self.walls is not None:
                self._launch(
                    k.wall_forces, n, d["pos"], d["vel"], d["angvel"], d["vel_pred"], d["angvel_pred"],
                    d["radius"], d["mass"], d["inertia"], d["inv_mass"], d["material"], d["wall_axis"],
                    d["wall_sign"], d["wall_coord"], d["wall_vel"], d["wall_vel_pred"], d["wall_table"],
                    d["wall_hist"], self.wall_springs, self.contact.law_code, self.contact.rolling, dt, dt,
                    d["force"], d["torque"], d["record"], d["pforce"],
                )  # fmt: skip
            if self.fluid is not None:
                for kernel, size, args in self.fluid_steps.forces:
                    self._launch(kernel, size, *args)
            if self.moving:
                self._wall_kick(n, (state.clock.step + taken + 1) * dt, dt)
            if self.fluid is not None and self.fluid_steps.kick:
                *before, (kernel, size, args) = self.fluid_steps.kick
                for launch in before:
                    self._launch(launch[0], launch[1], *launch[2])
                self._launch(kernel, size, *args, d["worst"])
            else:
                self._launch(
                    k.kick, n, d["vel"], d["angvel"], d["force"], d["torque"], d["inv_mass"],
                    d["inv_inertia"], dt, d["worst"],
                )  # fmt: skip
            if self.budget is not None:  # the springs of the last step are hist_next's since the swap
                self._book(n, dt)
        self.host_stale = True
        state.neighbors.moved2 = moved2
        self.on_device_at = end = state.clock.step + steps
        if self.fluid is not None and self.fluid.after_due(end, state.clock):
            self.fluid_due = end
        fluid_step = self.fluid_due == end
        coupling = fluid_step and self.fluid_steps.coupling
        if coupling:  # what the fluid's own step reads of the particles, made here
            for kernel, size, args in self.fluid_steps.coupling:
                self._launch(kernel, size, *args)
            _to_host(self.fluid_coupled)
        if self.stages is not None and self.stages.after_due(end, state.clock):
            self._particles_to_host(state)  # what the stage's test reads
            if self.stages.ends_at(end, state):  # the next stage begins from, and changes, it all
                self._rest_to_host(state)
                self.host_stale = False
        elif coupling:  # and the walls
            self._moving_walls_to_host(state)
        elif fluid_step:
            self._particles_to_host(state)
        if fluid_step and not coupling:  # (download leaves them: the host's step makes them after)
            _to_host(self.fluid_written)
        return steps, False

    def _book(self, n: int, dt: float) -> None:
        """The energy budget's shares of the step (EnergyBudget.finish_step)."""
        d, rows = self.d, self.rows
        wall_springs = self.walls is not None and self.wall_springs
        self._launch(
            self.book, n, d["pos"], d["vel_half"], d["angvel_half"], d["vel_pred"], d["angvel_pred"],
            d["vel"], d["angvel"], d["radius"], d["mass"], d["inertia"], d["inv_mass"], d["inv_inertia"],
            d["material"], rows.nbr, rows.count, self.hist_next, self.springs, d["table"],
            self.contact.law_code, self.contact.rolling, d["body_acc"], d["length"], d["periodic"],
            d["wall_axis"], d["wall_sign"], d["wall_coord"], d["wall_vel_half"], d["wall_vel_pred"],
            d["wall_vel"], d["wall_table"], d["wall_hist_last"], wall_springs, dt, d["budget_scratch"],
            d["booked"], d["no_spring"],
        )  # fmt: skip

    def _wall_kick(self, n: int, time: float, dt: float) -> None:
        """The particles' forces on the walls summed exactly, as on the CPU (push_sums), then
        the walls' second half kick (physics/walls.py WallMotion.kick)."""
        d = self.d
        self._launch(self.k.push_sums, n, d["pforce"], n, d["record"], d["sums"])
        self._launch(
            self.k.wall_motion_kick, 1, d["sums"], d["record"], d["attached"], d["attached_wall"], d["force"],
            d["mass"], d["body_acc"], d["wall_fluid_force"], d["wall_force"], d["wall_axis"], d["wall_sign"],
            d["wall_coord"], d["lower"], d["upper"], d["wall_area"], d["wall_mode"], d["wall_control"],
            d["wall_vel"], d["wall_acc"], time, dt,
        )  # fmt: skip

    def rebuild(self, state: State) -> None:
        """A new list from the positions, into the spare rows (grown until every row and cell
        fits), the springs carried into the free buffer (hist_next, whose springs are the last
        step's); then the spare rows become the list."""
        k = self.k
        d, n, skin = self.d, state.particles.count, state.neighbors.skin
        while True:
            d["longest"].copy_to_device(np.zeros(2, dtype=np.int32))
            self._launch(k.clear, self.cell_count.size, self.cell_count)
            self._launch(
                k.bin_particles, n, d["pos"], d["lower"], d["cell_size"], d["ncell"], self.cell_of,
                self.cell_count, self.cell_members, d["longest"],
            )  # fmt: skip
            self._launch(
                k.build_rows, n, d["pos"], d["radius"], d["length"], d["periodic"], d["ncell"], self.cell_of,
                self.cell_count, self.cell_members, skin, self.spare.nbr, self.spare.count,
                d["longest"],
            )  # fmt: skip
            row, cell = (int(v) for v in d["longest"].copy_to_host())
            if cell > self.cell_members.shape[1]:
                shape = (self.cell_count.size, cell + CELL_SLOTS)
                self.cell_members = self.cuda.device_array(shape, np.int32)
                continue
            if row > self.spare.nbr.shape[1]:
                self.spare = self._allocate(n, row + ROW_HEADROOM)
                continue
            break
        new = self.spare
        self._launch(k.find_mates, n, new.nbr, new.count, new.mate)
        width = new.nbr.shape[1]
        grown = width != self.rows.nbr.shape[1]
        if self.springs:
            carried = self._springs(n, width) if grown else self.hist_next
            old = self.rows
            self._launch(k.carry_springs, n, old.nbr, old.count, self.hist, new.nbr, new.count, carried)
            self.hist, self.hist_next = carried, self._springs(n, width) if grown else self.hist
        self.spare, self.rows = self.rows, new
        if grown:  # the spare grows with the list
            self.spare = self._allocate(n, width)
        d["ref_pos"].copy_to_device(d["pos"])
        self.builds += 1
