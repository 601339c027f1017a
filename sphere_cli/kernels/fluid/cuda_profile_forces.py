"""The 1D VANS fluid's force on the particles on a CUDA GPU (physics/device_steps.py): one
thread per particle, running the processor's own per-particle function
(kernels/fluid/profile_forces.py particle_profile_force); the fluid's column itself is solved on
the processor between coupling steps. Arguments as profile_forces's."""

from numba import cuda

from ..cuda_dem import for_gpu
from . import profile_forces as on_processor

particle_profile_force = for_gpu(on_processor.particle_profile_force)


@cuda.jit
def profile_forces(
    pos, vel, radius, selected, faces, centres, u, solid, top_no_slip, lid_velocity, rho, nu, exponent,
    solid_max, gravity, buoyancy_full, lift_coef, fluctuating, fluct, force, drag_coef, drag_x,
):  # fmt: skip
    """kernels/fluid/profile_forces.py profile_forces for particle i."""
    for i in range(cuda.grid(1), pos.shape[0], cuda.gridsize(1)):
        particle_profile_force(
            i, pos, vel, radius, selected, faces, centres, u, solid, top_no_slip, lid_velocity, rho, nu,
            exponent, solid_max, gravity, buoyancy_full, lift_coef, fluctuating, fluct, force, drag_coef,
            drag_x,
        )  # fmt: skip
