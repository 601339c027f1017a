"""The energy budget on a CUDA GPU (physics/device_steps.py): one thread per particle books its
share of the step with the processor's own function (kernels/observe/energy_budget.py
book_particle) on the device's full rows (kernels/cuda_dem.py), the partners below the particle
left out (their own rows book those pairs, as the processor's half rows do), the springs of the
last step read at the owner's slot. So each particle's share is the processor's, in the same
order: bitwise under Numba's CUDA simulator, to the GPU's FMA round-off on a device.

Arrays as in energy_budget.py; nbr, count (N,F), (N,) the full rows; hist (N,F,3) the springs
of the last step [m] (read when pair_springs); wall_hist (N,W,3) the wall springs of the last
step [m] (read when wall_springs); no_spring (3,) zeros. Every wall is booked for every
particle (the device keeps no near-wall list).
"""

import numpy as np
from numba import cuda

from ..cuda_dem import for_gpu
from . import energy_budget as on_processor

book_particle = for_gpu(on_processor.book_particle)
EVERY_WALL = np.uint64(0xFFFFFFFFFFFFFFFF)  # book_particle's mask of the walls to book


@cuda.jit
def book(
    pos, vel_half, angvel_half, vel_pred, angvel_pred, vel, angvel, radius, mass, inertia, inv_mass,
    inv_inertia, material, nbr, count, hist, pair_springs, table, law, rolling, body_acc, length,
    periodic, wall_axis, wall_sign, wall_coord, wall_vel_half, wall_vel_pred, wall_vel, wall_table,
    wall_hist, wall_springs, dt, scratch, booked, no_spring,
):  # fmt: skip
    """energy_budget.py accumulate_budget for particle i."""
    particles = (
        pos, vel_half, angvel_half, vel_pred, angvel_pred, vel, angvel, radius, mass, inertia, inv_mass,
        inv_inertia, material,
    )  # fmt: skip
    wall_arrays = (
        wall_axis, wall_sign, wall_coord, wall_vel_half, wall_vel_pred, wall_vel, wall_table, wall_hist,
        wall_springs,
    )  # fmt: skip
    for i in range(cuda.grid(1), booked.shape[0], cuda.gridsize(1)):
        springs = hist[i] if pair_springs else hist[0]  # (a (1,1,3) placeholder without friction)
        book_particle(
            i, i, nbr[i], count[i], springs, pair_springs, particles, wall_arrays, table, law, rolling,
            body_acc, length, periodic, dt, scratch, booked, no_spring, EVERY_WALL,
        )  # fmt: skip
