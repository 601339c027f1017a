"""The fluids' pressure solve on a CUDA GPU (simulation.device = "cuda"): physics/fluid/poisson.py
PoissonSolver, the same conjugate gradient and multigrid V-cycle, with its fields on the device
and kernels/fluid/cuda_poisson.py's kernels working on them (`OnGpu`, the place it is given).

A solve takes the caller's arrays: from the host (Darcy's step, on the processor) the right-hand
side, the coefficients and the first guess go to the device (six copies) and the solution comes
back (one copy); the device arrays of the Navier-Stokes step on the GPU (device_navier_stokes.py)
are taken as they are. Every sum of the iteration is the processor's exact sum of the same column
partial sums (69 words back from the device a sum), so the iterates, the iteration count and the
solution are the processor's, bitwise under Numba's simulator.

Imported only where a GPU is used (physics/device_steps.py), like every CUDA module."""

from __future__ import annotations

import numpy as np
from numba import cuda

from ...kernels.exact_sum import WORDS
from ...kernels.fluid import cuda_poisson
from ..device_steps import launch_shape, on_gpu_or_error
from .poisson import PoissonResult, PoissonSolver

# a level of at most this many cells is smoothed by Jacobi sweeps in one launch of one block (the
# coarsest level's 40 sweeps of 64 cells were 40 launches of latency alone, 40 of the 95 launches
# of an iteration at 64^3); a larger one (a level that cannot be coloured) in two launches a pair
ONE_BLOCK_CELLS = 32768
KERNELS = (
    "prepare_system", "apply_operator", "residual", "column_sums", "column_squares", "shift", "precondition",
    "cg_step", "new_direction", "jacobi_sweep", "coarsen_coefficients", "restrict", "prolong_add",
    "jacobi_smooth", "red_black_sweep", "column_dots",
)  # fmt: skip


class GpuKernels:
    """kernels/fluid/poisson.py's kernels by the same names and arguments, launched on the GPU
    (cuda_poisson.py), and column_words adding the partial sums there."""

    def __init__(self, launch: tuple, one_block: tuple):
        for name in KERNELS:
            setattr(self, name, getattr(cuda_poisson, name)[launch])
        self._pairs = cuda_poisson.jacobi_smooth_pairs[one_block]
        self._clear = cuda_poisson.clear_words[launch]
        self._add = cuda_poisson.add_words[launch]
        self._words = cuda.to_device(np.zeros(WORDS, dtype=np.int64))

    def jacobi_smooth_pairs(self, rhs, x, inv_diag, diag, ax, ay, az, px, py, ih2, omega, tmp, pairs) -> None:
        """`pairs` pairs of damped Jacobi sweeps of a whole level, x into tmp and back (poisson.py
        jacobi_smooth_pairs)."""
        if x.size <= ONE_BLOCK_CELLS:
            self._pairs(rhs, x, inv_diag, diag, ax, ay, az, px, py, ih2, omega, tmp, pairs)
            return
        nx = x.shape[0]
        for _ in range(pairs):
            self.jacobi_smooth(rhs, x, inv_diag, diag, ax, ay, az, px, py, ih2, omega, tmp, 0, nx)
            self.jacobi_smooth(rhs, tmp, inv_diag, diag, ax, ay, az, px, py, ih2, omega, x, 0, nx)

    def column_words(self, partial, first: int, last: int, words: np.ndarray) -> None:
        """words (host) = the exact sum of partial[first:last] (poisson.py column_words)."""
        self._clear(self._words)
        self._add(partial, first, last, self._words)
        self._words.copy_to_host(words)


class OnGpu:
    """A solver's fields on the GPU (physics/fluid/poisson.py OnProcessor's calls): kernels of one
    launch sized for the finest grid's columns, the caller's host arrays copied in and out."""

    fused = False  # no whole-grid loops in one compiled call: each kernel is a launch
    where = " (on the GPU)"

    def __init__(self, shape):
        # a thread a column (physics/device_steps.py launch_shape); one block of as many threads
        # for jacobi_smooth_pairs
        launch = launch_shape(int(shape[0]) * int(shape[1]))
        self.kernels = GpuKernels(launch, (1, launch[1]))
        self._fill = cuda_poisson.fill[launch]
        self.held = {}  # the device's copy of each argument of inputs(), by its place
        self.made = []  # the solver's own fields (zeros, array)

    def zeros(self, shape):
        self.made.append(cuda.to_device(np.zeros(shape)))
        return self.made[-1]

    def array(self, values: np.ndarray):
        self.made.append(cuda.to_device(np.ascontiguousarray(values, dtype=np.float64)))
        return self.made[-1]

    def device_bytes(self) -> int:
        """The bytes of the solver's fields and the copies of its inputs on the device."""
        return sum(a.nbytes for a in (*self.made, *self.held.values()))

    @staticmethod
    def put(field, values) -> None:
        """field = values (on the host or the device)."""
        on_host = isinstance(values, np.ndarray)
        field.copy_to_device(np.ascontiguousarray(values, dtype=np.float64) if on_host else values)

    @staticmethod
    def host(field) -> np.ndarray:
        return field.copy_to_host()

    def inputs(self, *arrays) -> tuple:
        """The caller's host arrays copied into the device's arrays kept for their places (the
        caller's device arrays as they are: the Navier-Stokes step on the GPU)."""
        out = []
        for place, values in enumerate(arrays):
            if not isinstance(values, np.ndarray):
                out.append(values)
                continue
            held = self.held.get(place)
            if held is None or held.shape != values.shape:
                held = self.held[place] = cuda.device_array(values.shape)
            held.copy_to_device(np.ascontiguousarray(values, dtype=np.float64))
            out.append(held)
        return tuple(out)

    @staticmethod
    def output(field, x) -> None:
        if field is x:
            return
        if x.flags.c_contiguous:
            field.copy_to_host(x)
        else:
            x[...] = field.copy_to_host()

    def fill(self, field, value: float) -> None:
        self._fill(field, value)

    @staticmethod
    def scale(field, exponent: int) -> None:
        """field *= 2^exponent, exactly (on the host: a right-hand side far from unit size is rare)."""
        values = field.copy_to_host()
        np.ldexp(values, exponent, out=values)
        field.copy_to_device(values)


class GpuPoissonSolver(PoissonSolver):
    """PoissonSolver with its fields on the GPU, whose failures (out of memory above all) are the
    user's error naming simulation.device, not a traceback (its solves run in the fluid's step on
    the host, outside DeviceSteps.run)."""

    def solve(self, *arguments) -> PoissonResult:
        return on_gpu_or_error(lambda: super(GpuPoissonSolver, self).solve(*arguments))

    def explicit_step(self, *arguments) -> None:
        on_gpu_or_error(lambda: super(GpuPoissonSolver, self).explicit_step(*arguments))


def on_gpu(solver: PoissonSolver) -> PoissonSolver:
    """The same solver with its fields on the GPU."""
    if isinstance(solver, GpuPoissonSolver):
        return solver
    return on_gpu_or_error(lambda: GpuPoissonSolver.like(solver, OnGpu(solver.grid.shape)))
