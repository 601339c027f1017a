"""The pressure and pore-pressure solver's kernels (kernels/fluid/poisson.py) on a CUDA GPU
(physics/fluid/device_poisson.py): one thread a grid column, running the processor's own column
functions, so each column's cells and partial sum are the processor's; the partial sums are added
exactly by integer atomics (kernels/exact_sum.py, as cuda_dem.py push_sums adds the walls'), so
every sum is the processor's too, whatever the order of the threads, and so are the iterates.

Arguments and the columns [lo, hi) as in poisson.py; the kernels are launched over any number of
threads (each takes the columns cuda.grid(1), then on by cuda.gridsize(1)), but for
jacobi_smooth_pairs, one block's. A red-black sweep runs
one colour of each column of the planes [lo, hi): the cells of one colour read only the other's,
so the order of their updates changes nothing."""

import math

from numba import cuda

from ..cuda_dem import BINS, exact_parts, for_gpu
from . import poisson as on_processor

prepare_column = for_gpu(on_processor.prepare_column)
apply_column = for_gpu(on_processor.apply_column)
residual_column = for_gpu(on_processor.residual_column)
sum_column = for_gpu(on_processor.sum_column)
square_column = for_gpu(on_processor.square_column)
shift_column = for_gpu(on_processor.shift_column)
precondition_column = for_gpu(on_processor.precondition_column)
cg_step_column = for_gpu(on_processor.cg_step_column)
direction_column = for_gpu(on_processor.direction_column)
jacobi_sweep_column = for_gpu(on_processor.jacobi_sweep_column)
coarsen_column = for_gpu(on_processor.coarsen_column)
restrict_column = for_gpu(on_processor.restrict_column)
prolong_column = for_gpu(on_processor.prolong_column)
smooth_column = for_gpu(on_processor.smooth_column)
red_black_column = for_gpu(on_processor.red_black_column)
dot_column = for_gpu(on_processor.dot_column)


@cuda.jit
def prepare_system(
    b, c, ax, ay, az, px, py, bottom, top, bottom_value, top_value, ih2, rhs, diag, inv, partial
):
    for col in range(cuda.grid(1), b.shape[0] * b.shape[1], cuda.gridsize(1)):
        prepare_column(
            b, c, ax, ay, az, px, py, bottom, top, bottom_value, top_value, ih2, rhs, diag, inv, partial, col
        )


@cuda.jit
def apply_operator(x, diag, ax, ay, az, px, py, ih2, out, partial, lo, hi):
    for col in range(lo * x.shape[1] + cuda.grid(1), hi * x.shape[1], cuda.gridsize(1)):
        apply_column(x, diag, ax, ay, az, px, py, ih2, out, partial, col)


@cuda.jit
def residual(rhs, x, diag, ax, ay, az, px, py, ih2, r, partial, lo, hi):
    for col in range(lo * x.shape[1] + cuda.grid(1), hi * x.shape[1], cuda.gridsize(1)):
        residual_column(rhs, x, diag, ax, ay, az, px, py, ih2, r, partial, col)


@cuda.jit
def column_sums(x, partial, lo, hi):
    for col in range(lo * x.shape[1] + cuda.grid(1), hi * x.shape[1], cuda.gridsize(1)):
        sum_column(x, partial, col)


@cuda.jit
def column_squares(x, partial, lo, hi):
    for col in range(lo * x.shape[1] + cuda.grid(1), hi * x.shape[1], cuda.gridsize(1)):
        square_column(x, partial, col)


@cuda.jit
def shift(x, amount, lo, hi):
    for col in range(lo * x.shape[1] + cuda.grid(1), hi * x.shape[1], cuda.gridsize(1)):
        shift_column(x, amount, col)


@cuda.jit
def precondition(r, inv_diag, z, partial_rz, partial_z, lo, hi):
    for col in range(lo * r.shape[1] + cuda.grid(1), hi * r.shape[1], cuda.gridsize(1)):
        precondition_column(r, inv_diag, z, partial_rz, partial_z, col)


@cuda.jit
def cg_step(x, r, p, q, alpha, inv_diag, z, partial_rr, partial_rz, partial_z, lo, hi):
    for col in range(lo * x.shape[1] + cuda.grid(1), hi * x.shape[1], cuda.gridsize(1)):
        cg_step_column(x, r, p, q, alpha, inv_diag, z, partial_rr, partial_rz, partial_z, col)


@cuda.jit
def new_direction(p, z, beta, z_mean, lo, hi):
    for col in range(lo * p.shape[1] + cuda.grid(1), hi * p.shape[1], cuda.gridsize(1)):
        direction_column(p, z, beta, z_mean, col)


@cuda.jit
def jacobi_sweep(rhs, x, diag, inv_diag, ax, ay, az, px, py, ih2, x_new, partial):
    for col in range(cuda.grid(1), x.shape[0] * x.shape[1], cuda.gridsize(1)):
        jacobi_sweep_column(rhs, x, diag, inv_diag, ax, ay, az, px, py, ih2, x_new, partial, col)


@cuda.jit
def coarsen_coefficients(c, ax, ay, az, fx, fy, fz, cc, axc, ayc, azc):
    for col in range(cuda.grid(1), cc.shape[0] * cc.shape[1], cuda.gridsize(1)):
        coarsen_column(c, ax, ay, az, fx, fy, fz, cc, axc, ayc, azc, col)


@cuda.jit
def restrict(fine, fx, fy, fz, coarse, lo, hi):
    for col in range(lo * coarse.shape[1] + cuda.grid(1), hi * coarse.shape[1], cuda.gridsize(1)):
        restrict_column(fine, fx, fy, fz, coarse, col)


@cuda.jit
def prolong_add(coarse, fx, fy, fz, fine, lo, hi):
    for col in range(lo * fine.shape[1] + cuda.grid(1), hi * fine.shape[1], cuda.gridsize(1)):
        prolong_column(coarse, fx, fy, fz, fine, col)


@cuda.jit
def jacobi_smooth(rhs, x, inv_diag, diag, ax, ay, az, px, py, ih2, omega, out, lo, hi):
    for col in range(lo * x.shape[1] + cuda.grid(1), hi * x.shape[1], cuda.gridsize(1)):
        smooth_column(rhs, x, inv_diag, diag, ax, ay, az, px, py, ih2, omega, out, col)


@cuda.jit
def jacobi_smooth_pairs(rhs, x, inv_diag, diag, ax, ay, az, px, py, ih2, omega, tmp, pairs):
    """poisson.py jacobi_smooth_pairs in one launch of one block (a small level: the coarsest's
    40 sweeps were 40 launches): its threads share the columns and wait for each other after each
    sweep, which reads only the last one's values."""
    columns = x.shape[0] * x.shape[1]
    for _ in range(pairs):
        for col in range(cuda.threadIdx.x, columns, cuda.blockDim.x):
            smooth_column(rhs, x, inv_diag, diag, ax, ay, az, px, py, ih2, omega, tmp, col)
        cuda.syncthreads()
        for col in range(cuda.threadIdx.x, columns, cuda.blockDim.x):
            smooth_column(rhs, tmp, inv_diag, diag, ax, ay, az, px, py, ih2, omega, x, col)
        cuda.syncthreads()


@cuda.jit
def red_black_sweep(rhs, x, inv_diag, ax, ay, az, px, py, ih2, color, lo, hi):
    for col in range(lo * x.shape[1] + cuda.grid(1), hi * x.shape[1], cuda.gridsize(1)):
        red_black_column(rhs, x, inv_diag, ax, ay, az, px, py, ih2, color, col)


@cuda.jit
def column_dots(r, z, partial_rz, partial_z, lo, hi):
    for col in range(lo * r.shape[1] + cuda.grid(1), hi * r.shape[1], cuda.gridsize(1)):
        dot_column(r, z, partial_rz, partial_z, col)


@cuda.jit
def fill(x, value):
    """Every cell of x set to value."""
    for col in range(cuda.grid(1), x.shape[0] * x.shape[1], cuda.gridsize(1)):
        i, j = col // x.shape[1], col % x.shape[1]
        for k in range(x.shape[2]):
            x[i, j, k] = value


@cuda.jit
def scale(a, factor, out):
    """out = factor a, element by element (flat arrays of one size)."""
    for n in range(cuda.grid(1), a.shape[0], cuda.gridsize(1)):
        out[n] = factor * a[n]


@cuda.jit
def add_words(partial, first, last, words):
    """words (WORDS,) int64, zero on entry, += the exact sum of partial[first:last] (poisson.py
    column_words), by integer atomics: exact, so the same whatever the order of the threads."""
    for col in range(first + cuda.grid(1), last, cuda.gridsize(1)):
        value = partial[col]
        if value == 0.0:
            continue
        if not math.isfinite(value):
            cuda.atomic.add(words, BINS, 1)
            continue
        k, low, middle, high = exact_parts(value)  # as kernels/exact_sum.py add_exact adds them
        cuda.atomic.add(words, k, low)
        cuda.atomic.add(words, k + 1, middle)
        cuda.atomic.add(words, k + 2, high)


@cuda.jit
def clear_words(words):
    for k in range(cuda.grid(1), words.shape[0], cuda.gridsize(1)):
        words[k] = 0
