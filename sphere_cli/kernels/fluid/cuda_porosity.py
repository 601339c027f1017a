"""The porosity of the fluid cells from the particles on a CUDA GPU (physics/device_steps.py), and
the particles sorted by fluid cell, which it and the drag's sums per cell (kernels/fluid/
cuda_drag.py) gather from: the processor's own functions (kernels/fluid/porosity.py bin_particle
and sample_cell), one thread per particle or per cell.

The sort gives the processor's stable counting sort (kernels/neighbors.py counting_sort): each
cell's particles counted by atomics, a prefix sum by one block, a fill whose order within a cell
depends on the scheduling, then each cell's particles sorted by index (by its own thread:
insertion for a few tens, a heap sort beyond). Counts are integers: an
atomic add is exact in any order, so every sum over a cell's particles is the processor's,
bitwise, whatever the launch.

Arrays as in porosity.py; cell_count (C,) int32 (zero between sorts: sort_cells zeroes it),
cell_start (C+1,) int32, cell_next (C,) int32, cell_order (N,) int32; clamped (1,) int32: the
cells whose porosity was clamped at 0 by the last sample_cells.
"""

from numba import cuda, int64

from ..cuda_dem import for_gpu
from . import porosity as on_processor

bin_particle = for_gpu(on_processor.bin_particle)
sample_cell = for_gpu(on_processor.sample_cell)


@cuda.jit
def bin_in_fluid_cells(pos, origin, spacing, shape, periodic, bin_of, wrapped, cell_count, clamped):
    """porosity.py bin_particles for particle i, counted in its cell; thread 0 zeroes clamped[0]
    for the sample_cells that follows."""
    for i in range(cuda.grid(1), pos.shape[0], cuda.gridsize(1)):
        bin_particle(i, pos, origin, spacing, shape, periodic, bin_of, wrapped)
        cuda.atomic.add(cell_count, bin_of[i], 1)
    if cuda.grid(1) == 0:
        clamped[0] = 0


@cuda.jit
def count_in_cells(cell_of, cell_count):
    """Each particle counted in its cell."""
    for i in range(cuda.grid(1), cell_of.shape[0], cuda.gridsize(1)):
        cuda.atomic.add(cell_count, cell_of[i], 1)


# the most threads a block has (CUDA's limit): the places of cell_starts's partial sums
SCAN_WIDTH = 1024


@cuda.jit
def cell_starts(cell_count, cell_start, cell_next):
    """Where each cell's particles begin in cell_order (an exclusive prefix sum of the counts),
    by the first block alone (the others return): each of its threads sums a contiguous run of
    cells, its first thread turns those sums into the runs' starts, then each thread writes its
    run's. Integer sums: the same in any launch. (One GPU thread over every cell, as before,
    waits for each count in turn: 54 000 loads one after another at 30 x 30 x 60 cells.)"""
    if cuda.blockIdx.x != 0:
        return
    runs = cuda.shared.array(SCAN_WIDTH, int64)
    t = cuda.threadIdx.x
    width = min(cuda.blockDim.x, SCAN_WIDTH)
    cells = cell_count.shape[0]
    run = (cells + width - 1) // width
    first = min(t * run, cells)
    last = min(first + run, cells)
    if t < width:
        total = 0
        for c in range(first, last):
            total += cell_count[c]
        runs[t] = total
    cuda.syncthreads()
    if t == 0:
        total = 0
        for r in range(width):
            here = runs[r]
            runs[r] = total
            total += here
        cell_start[cells] = total
    cuda.syncthreads()
    if t < width:
        total = runs[t]
        for c in range(first, last):
            cell_start[c] = total
            cell_next[c] = total
            total += cell_count[c]


@cuda.jit
def fill_cells(cell_of, cell_next, cell_order):
    """Particle i into a free place of its cell's part of cell_order."""
    for i in range(cuda.grid(1), cell_of.shape[0], cuda.gridsize(1)):
        cell_order[cuda.atomic.add(cell_next, cell_of[i], 1)] = i


# a cell with more particles than this is heap-sorted (k log k), fewer by insertion (k^2, fast
# for the few tens of particles of a cell a few diameters wide)
INSERTION_MOST = 32


@cuda.jit(device=True, inline=True)
def sort_cell(c, cell_start, cell_order, cell_count):
    """Cell c's particles in cell_order sorted by index; its count zeroed for the next sort.
    (Distinct indices have one ascending order: either sort gives it.)"""
    first = cell_start[c]
    last = cell_start[c + 1]
    if last - first <= INSERTION_MOST:
        for k in range(first + 1, last):
            i = cell_order[k]
            m = k
            while m > first and cell_order[m - 1] > i:
                cell_order[m] = cell_order[m - 1]
                m -= 1
            cell_order[m] = i
    else:
        size = last - first
        for top in range(size // 2 - 1, -1, -1):
            _sift_down(cell_order, first, top, size)
        for end in range(size - 1, 0, -1):
            largest = cell_order[first]
            cell_order[first] = cell_order[first + end]
            cell_order[first + end] = largest
            _sift_down(cell_order, first, 0, end)
    cell_count[c] = 0


@cuda.jit(device=True, inline=True)
def _sift_down(order, first, node, size):
    """The heap order[first:first + size] (largest at its root) restored below `node`."""
    while True:
        child = 2 * node + 1
        if child >= size:
            return
        if child + 1 < size and order[first + child + 1] > order[first + child]:
            child += 1
        if order[first + node] >= order[first + child]:
            return
        swap = order[first + node]
        order[first + node] = order[first + child]
        order[first + child] = swap
        node = child


@cuda.jit
def sort_cells(cell_start, cell_order, cell_count):
    for c in range(cuda.grid(1), cell_count.shape[0], cuda.gridsize(1)):
        sort_cell(c, cell_start, cell_order, cell_count)


@cuda.jit
def sample_cells(
    wrapped, vel, radius, origin, spacing, shape, periodic, sampling_radius, subdivisions, largest, reach,
    cell_start, order, want_means, porosity, mean_velocity, mean_diameter, clamped,
):  # fmt: skip
    """porosity.py sample_cells for cell c, the clamped cells counted in clamped[0]."""
    for c in range(cuda.grid(1), porosity.size, cuda.gridsize(1)):
        if sample_cell(
            c, wrapped, vel, radius, origin, spacing, shape, periodic, sampling_radius, subdivisions, largest,
            reach, cell_start, order, want_means, porosity, mean_velocity, mean_diameter,
        ):  # fmt: skip
            cuda.atomic.add(clamped, 0, 1)
