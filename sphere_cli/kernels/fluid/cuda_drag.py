"""The Navier-Stokes fluid's drag on the particles on a CUDA GPU (physics/device_steps.py), one
thread per particle or per fluid cell running the processor's own functions (kernels/fluid/
drag.py drag_on_particle, kick_with_drag and exchange_cell, kernels/fluid/porosity.py
bin_particle); the fluid's grid itself is solved on the processor between coupling steps.

The sums over each cell's particles (the self-induced velocity's drag coefficients every step,
the momentum exchange at each fluid step) gather from the particles sorted by cell
(kernels/fluid/cuda_porosity.py), each cell's particles in index order: the processor's sums,
bitwise, whatever the launch.

Arrays as in drag.py; below (1,) int64: the particle-steps in cells under the porosity floor.
"""

from numba import cuda

from ..cuda_dem import for_gpu
from . import drag as on_processor
from .cuda_porosity import bin_particle, sort_cell

drag_on_particle = for_gpu(on_processor.drag_on_particle)
kick_with_drag = for_gpu(on_processor.kick_with_drag)
exchange_cell = for_gpu(on_processor.exchange_cell)


@cuda.jit
def drag_forces(
    pos, origin, spacing, cells, periodic, wrapped, law, rho, mu, floor, pressure_force, cell_of, vel,
    radius, inv_mass, u, phi, grad_p, dt, cell_share, cell_diameter, cell_velocity, disturbance, force,
    f_other, coef, f_drag, below,
):  # fmt: skip
    """physics/fluid/drag.py FluidParticleDrag.forces for particle i: its fluid cell, then the
    pressure-gradient force and the drag added to its force (never the initial state's: the host
    computes that one)."""
    for i in range(cuda.grid(1), pos.shape[0], cuda.gridsize(1)):
        bin_particle(i, pos, origin, spacing, cells, periodic, cell_of, wrapped)
        if drag_on_particle(
            i, law, rho, mu, floor, pressure_force, cell_of, vel, radius, inv_mass, u, phi, grad_p, dt, False,
            cell_share, cell_diameter, cell_velocity, disturbance, force, f_other, coef, f_drag,
        ):  # fmt: skip
            cuda.atomic.add(below, 0, 1)


@cuda.jit
def cell_coefficients(cell_start, cell_order, coef, cell_count, cell_coef):
    """drag.py cell_coefficients for cell c: its particles sorted by index, their coefficients
    summed in that order."""
    for c in range(cuda.grid(1), cell_coef.shape[0], cuda.gridsize(1)):
        sort_cell(c, cell_start, cell_order, cell_count)
        total = 0.0
        for k in range(cell_start[c], cell_start[c + 1]):
            total += coef[cell_order[k]]
        cell_coef[c] = total


@cuda.jit
def exchange(
    start, order, impulse, coef, inv_mass, f_other, vel, radius, u, grad_p, pressure_exchanged, fluid_dt,
    inv_cell_volume, disturbance, f_i, f_i_coef, f_exchange, predicted, solid,
):  # fmt: skip
    """drag.py exchange for cell c, its particles sorted (cuda_porosity.py sort_cells)."""
    for c in range(cuda.grid(1), f_i_coef.shape[0], cuda.gridsize(1)):
        exchange_cell(
            c, start, order, impulse, coef, inv_mass, f_other, vel, radius, u, grad_p, pressure_exchanged,
            fluid_dt, inv_cell_volume, disturbance, f_i, f_i_coef, f_exchange, predicted, solid,
        )  # fmt: skip


@cuda.jit
def drag_kick(
    vel, angvel, torque, inv_mass, inv_inertia, cell_of, u, coef, f_other, dt, force, f_drag, impulse,
    disturbance, cell_coef, cell_volume, weight, rate, band_decay, mu, nu, worst,
):  # fmt: skip
    """drag.py drag_kick for particle i, in place of the particles' own kick (kernels/cuda_dem.py
    kick): thread 0 zeroes worst[0] for the next step's kick-drift, as that one does."""
    for i in range(cuda.grid(1), vel.shape[0], cuda.gridsize(1)):
        kick_with_drag(
            i, vel, angvel, torque, inv_mass, inv_inertia, cell_of, u, coef, f_other, dt, force, f_drag,
            impulse, disturbance, cell_coef, cell_volume, weight, rate, band_decay, mu, nu,
        )  # fmt: skip
        if i == 0:
            worst[0] = 0.0
