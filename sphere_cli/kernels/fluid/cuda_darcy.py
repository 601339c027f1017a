"""The Darcy fluid's force on the particles on a CUDA GPU (physics/device_steps.py): one thread
per particle, running the processor's own per-particle function (kernels/fluid/darcy.py
particle_pressure_force), and its push on an impermeable top wall on one thread (push_wall); the
pore pressure itself is solved on the processor between coupling steps. Arguments as
add_pressure_forces's and push_wall's."""

from numba import cuda

from ..cuda_dem import for_gpu
from . import darcy as on_processor

particle_pressure_force = for_gpu(on_processor.particle_pressure_force)
wall_push = for_gpu(on_processor.push_wall)


@cuda.jit
def pressure_forces(pos, radius, grad, porosity, whole, origin, spacing, periodic, rho_f, gravity, force):
    """kernels/fluid/darcy.py add_pressure_forces for particle n."""
    for n in range(cuda.grid(1), pos.shape[0], cuda.gridsize(1)):
        particle_pressure_force(
            n, pos, radius, grad, porosity, whole, origin, spacing, periodic, rho_f, gravity, force
        )


@cuda.jit
def push_wall(coord, top, bottom, height, pressure, stiffness, area, fluid_force):
    """kernels/fluid/darcy.py push_wall, on one thread."""
    if cuda.grid(1) == 0:
        wall_push(coord, top, bottom, height, pressure, stiffness, area, fluid_force)
