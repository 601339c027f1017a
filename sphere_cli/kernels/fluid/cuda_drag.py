"""The Navier-Stokes fluid's drag on the particles on a CUDA GPU (physics/device_steps.py), one
thread per particle running the processor's own per-particle functions (kernels/fluid/drag.py
drag_on_particle and kick_with_drag, kernels/fluid/porosity.py bin_particle); the fluid's grid
itself is solved on the processor between coupling steps.

The self-induced velocity's correction needs the sum of the drag coefficients of each cell's
particles, which the processor takes in particle order (drag.py cell_coefficients). Here the
particles are sorted by cell (a count by atomics, a prefix sum, a fill whose order within a cell
depends on the scheduling), then each cell's thread sorts its own particles by index and sums in
that order: the processor's sum, bitwise, whatever the launch. The counts are integers: an atomic
add is exact in any order.

Arrays as in drag.py; cell_count (C,) int32 (zero between steps: the sum zeroes it), cell_start
(C+1,) int32, cell_next (C,) int32, cell_order (N,) int32, below (1,) int64: the particle-steps in
cells under the porosity floor since the host last read it.
"""

from numba import cuda

from ..cuda_dem import for_gpu
from . import drag as on_processor
from . import porosity

bin_particle = for_gpu(porosity.bin_particle)
drag_on_particle = for_gpu(on_processor.drag_on_particle)
kick_with_drag = for_gpu(on_processor.kick_with_drag)


@cuda.jit
def drag_forces(
    pos, origin, spacing, cells, periodic, wrapped, law, rho, mu, floor, pressure_force, cell_of, vel,
    radius, inv_mass, u, phi, grad_p, dt, cell_share, cell_diameter, cell_velocity, disturbance, force,
    f_other, coef, f_drag, below,
):  # fmt: skip
    """physics/fluid/drag.py FluidParticleDrag.forces for particle i: its fluid cell, then the
    pressure-gradient force and the drag added to its force (never the initial state's: the host
    computes that one)."""
    i = cuda.grid(1)
    if i >= pos.shape[0]:
        return
    bin_particle(i, pos, origin, spacing, cells, periodic, cell_of, wrapped)
    if drag_on_particle(
        i, law, rho, mu, floor, pressure_force, cell_of, vel, radius, inv_mass, u, phi, grad_p, dt, False,
        cell_share, cell_diameter, cell_velocity, disturbance, force, f_other, coef, f_drag,
    ):  # fmt: skip
        cuda.atomic.add(below, 0, 1)


@cuda.jit
def count_in_cells(cell_of, cell_count):
    """Each particle counted in its cell."""
    i = cuda.grid(1)
    if i < cell_of.shape[0]:
        cuda.atomic.add(cell_count, cell_of[i], 1)


@cuda.jit
def cell_starts(cell_count, cell_start, cell_next):
    """One thread: where each cell's particles begin in cell_order (a prefix sum of the counts)."""
    if cuda.grid(1) != 0:
        return
    total = 0
    for c in range(cell_count.shape[0]):
        cell_start[c] = total
        cell_next[c] = total
        total += cell_count[c]
    cell_start[cell_count.shape[0]] = total


@cuda.jit
def fill_cells(cell_of, cell_next, cell_order):
    """Particle i into a free place of its cell's part of cell_order."""
    i = cuda.grid(1)
    if i < cell_of.shape[0]:
        cell_order[cuda.atomic.add(cell_next, cell_of[i], 1)] = i


@cuda.jit
def cell_coefficients(cell_start, cell_order, coef, cell_count, cell_coef):
    """drag.py cell_coefficients for cell c: its particles sorted by index, their coefficients
    summed in that order; its count zeroed for the next step."""
    c = cuda.grid(1)
    if c >= cell_coef.shape[0]:
        return
    first = cell_start[c]
    last = cell_start[c + 1]
    for k in range(first + 1, last):  # insertion sort: a cell holds a few tens of particles
        i = cell_order[k]
        m = k
        while m > first and cell_order[m - 1] > i:
            cell_order[m] = cell_order[m - 1]
            m -= 1
        cell_order[m] = i
    total = 0.0
    for k in range(first, last):
        total += coef[cell_order[k]]
    cell_coef[c] = total
    cell_count[c] = 0


@cuda.jit
def drag_kick(
    vel, angvel, torque, inv_mass, inv_inertia, cell_of, u, coef, f_other, dt, force, f_drag, impulse,
    disturbance, cell_coef, cell_volume, weight, rate, band_decay, mu, nu, worst,
):  # fmt: skip
    """drag.py drag_kick for particle i, in place of the particles' own kick (kernels/cuda_dem.py
    kick): thread 0 zeroes worst[0] for the next step's kick-drift, as that one does."""
    i = cuda.grid(1)
    if i >= vel.shape[0]:
        return
    kick_with_drag(
        i, vel, angvel, torque, inv_mass, inv_inertia, cell_of, u, coef, f_other, dt, force, f_drag, impulse,
        disturbance, cell_coef, cell_volume, weight, rate, band_decay, mu, nu,
    )  # fmt: skip
    if i == 0:
        worst[0] = 0.0
