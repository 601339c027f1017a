"""The Darcy pore-pressure step's grid kernels (kernels/fluid/pore_pressure.py, and poisson.py
face_means) on a CUDA GPU (physics/fluid/device_pore_pressure.py): one thread a grid column (i, j),
running the processor's own column functions, so each column's values are the processor's.
Arguments as in pore_pressure.py; clamp_porosity adds its count of clamped cells to clamped (1,)
int64 (integer atomics: exact in any order). Each kernel strides over the grid's columns (thread t
of T takes t, t + T, ...), so any launch gives the same values. cut_fixed_faces writes zeros into
faces a neighbouring column may zero too: the same value, whatever the order."""

from numba import cuda

from ..cuda_dem import for_gpu
from . import poisson
from . import pore_pressure as on_processor

clamp_porosity_column = for_gpu(on_processor.clamp_porosity_column)
kozeny_carman_column = for_gpu(on_processor.kozeny_carman_column)
constant_permeability_column = for_gpu(on_processor.constant_permeability_column)
face_means_column = for_gpu(poisson.face_means_column)
solid_divergence_column = for_gpu(on_processor.solid_divergence_column)
backward_euler_system_column = for_gpu(on_processor.backward_euler_system_column)
eliminate_fixed_cells_column = for_gpu(on_processor.eliminate_fixed_cells_column)
cut_fixed_faces_column = for_gpu(on_processor.cut_fixed_faces_column)
pressure_gradient_column = for_gpu(on_processor.pressure_gradient_column)
darcy_velocity_column = for_gpu(on_processor.darcy_velocity_column)


@cuda.jit
def clamp_porosity(phi, phi_min, phi_max, phi_used, clamped):
    for col in range(cuda.grid(1), phi.shape[0] * phi.shape[1], cuda.gridsize(1)):
        count = clamp_porosity_column(
            phi, phi_min, phi_max, phi_used, col // phi.shape[1], col % phi.shape[1]
        )
        if count:
            cuda.atomic.add(clamped, 0, count)


@cuda.jit
def kozeny_carman(phi_used, kc, k):
    for col in range(cuda.grid(1), k.shape[0] * k.shape[1], cuda.gridsize(1)):
        kozeny_carman_column(phi_used, kc, k, col // k.shape[1], col % k.shape[1])


@cuda.jit
def constant_permeability(value, k):
    for col in range(cuda.grid(1), k.shape[0] * k.shape[1], cuda.gridsize(1)):
        constant_permeability_column(value, k, col // k.shape[1], col % k.shape[1])


@cuda.jit
def face_means(cell, periodic_x, periodic_y, harmonic, ax, ay, az):
    for col in range(cuda.grid(1), cell.shape[0] * cell.shape[1], cuda.gridsize(1)):
        i, j = col // cell.shape[1], col % cell.shape[1]
        face_means_column(cell, periodic_x, periodic_y, harmonic, ax, ay, az, i, j)


@cuda.jit
def solid_divergence(phi_used, phi_raw, dphi_dt, vbar, ih, periodic, source):
    for col in range(cuda.grid(1), source.shape[0] * source.shape[1], cuda.gridsize(1)):
        i, j = col // source.shape[1], col % source.shape[1]
        solid_divergence_column(phi_used, phi_raw, dphi_dt, vbar, ih, periodic, source, i, j)


@cuda.jit
def backward_euler_system(p, phi_used, source, beta, mu, dt, c, b):
    for col in range(cuda.grid(1), p.shape[0] * p.shape[1], cuda.gridsize(1)):
        backward_euler_system_column(
            p, phi_used, source, beta, mu, dt, c, b, col // p.shape[1], col % p.shape[1]
        )


@cuda.jit
def eliminate_fixed_cells(fixed, fixed_value, ax, ay, az, ih2, periodic, c, b):
    for col in range(cuda.grid(1), fixed.shape[0] * fixed.shape[1], cuda.gridsize(1)):
        i, j = col // fixed.shape[1], col % fixed.shape[1]
        eliminate_fixed_cells_column(fixed, fixed_value, ax, ay, az, ih2, periodic, c, b, i, j)


@cuda.jit
def cut_fixed_faces(fixed, ax, ay, az, periodic):
    for col in range(cuda.grid(1), fixed.shape[0] * fixed.shape[1], cuda.gridsize(1)):
        cut_fixed_faces_column(fixed, ax, ay, az, periodic, col // fixed.shape[1], col % fixed.shape[1])


@cuda.jit
def pressure_gradient(p, ih, periodic, bottom_dirichlet, top_dirichlet, bottom_value, top_value, grad):
    for col in range(cuda.grid(1), p.shape[0] * p.shape[1], cuda.gridsize(1)):
        i, j = col // p.shape[1], col % p.shape[1]
        pressure_gradient_column(
            p, ih, periodic, bottom_dirichlet, top_dirichlet, bottom_value, top_value, grad, i, j
        )  # fmt: skip


@cuda.jit
def darcy_velocity(
    p, ax, ay, az, ih, periodic, bottom_dirichlet, top_dirichlet, bottom_value, top_value, phi_used, mu, v
):  # fmt: skip
    for col in range(cuda.grid(1), p.shape[0] * p.shape[1], cuda.gridsize(1)):
        i, j = col // p.shape[1], col % p.shape[1]
        darcy_velocity_column(
            p, ax, ay, az, ih, periodic, bottom_dirichlet, top_dirichlet, bottom_value, top_value, phi_used,
            mu, v, i, j,
        )  # fmt: skip
