"""The Navier-Stokes fluid step's grid kernels (kernels/fluid/navier_stokes.py) on a CUDA GPU
(physics/fluid/navier_stokes.py NavierStokesSolver with its fields there): one thread a grid
column (i, j), running the processor's own column functions, so each column's values are the
processor's. Arguments as in navier_stokes.py (lo, hi: the planes lo .. hi - 1, wrapped, of
advective_fluxes, viscous_stresses and predict); face_coefficients takes the (nx + 1) x (ny + 1)
columns of the face arrays. Each kernel strides over its columns
(thread t of T takes t, t + T, ...), so any launch gives the same values."""

from numba import cuda

from ..cuda_dem import for_gpu
from . import navier_stokes as on_processor

edge_porosity_column = for_gpu(on_processor.edge_porosity_column)
pressure_gradient_column = for_gpu(on_processor.pressure_gradient_column)
viscous_stresses_column = for_gpu(on_processor.viscous_stresses_column)
advective_fluxes_column = for_gpu(on_processor.advective_fluxes_column)
predict_column = for_gpu(on_processor.predict_column)
face_coefficients_column = for_gpu(on_processor.face_coefficients_column)
pressure_rhs_column = for_gpu(on_processor.pressure_rhs_column)
correct_column = for_gpu(on_processor.correct_column)
cell_velocity_column = for_gpu(on_processor.cell_velocity_column)
add_grid_motion_column = for_gpu(on_processor.add_grid_motion_column)
add_grid_source_column = for_gpu(on_processor.add_grid_source_column)
wrap = for_gpu(on_processor._wrap)  # the plane lo + t of a slab, wrapped (lo may be -1)


@cuda.jit
def edge_porosity(phi, edges):
    for col in range(cuda.grid(1), phi.shape[0] * phi.shape[1], cuda.gridsize(1)):
        edge_porosity_column(phi, edges, col // phi.shape[1], col % phi.shape[1])


@cuda.jit
def pressure_gradient(p, spacing, p_kind, p_bound, grad_p):
    for col in range(cuda.grid(1), p.shape[0] * p.shape[1], cuda.gridsize(1)):
        pressure_gradient_column(p, spacing, p_kind, p_bound, grad_p, col // p.shape[1], col % p.shape[1])


@cuda.jit
def viscous_stresses(v_face, phi, edges, spacing, bc_sign, normal, shear, lo, hi):
    nx, ny = phi.shape[0], phi.shape[1]
    for col in range(cuda.grid(1), (hi - lo) * ny, cuda.gridsize(1)):
        i, j = wrap(lo + col // ny, nx), col % ny
        viscous_stresses_column(v_face, phi, edges, spacing, bc_sign, normal, shear, i, j)


@cuda.jit
def advective_fluxes(v_face, phi, edges, bc_sign, flux, lo, hi):
    nx, ny = phi.shape[0], phi.shape[1]
    for col in range(cuda.grid(1), (hi - lo) * ny, cuda.gridsize(1)):
        advective_fluxes_column(v_face, phi, edges, bc_sign, flux, wrap(lo + col // ny, nx), col % ny)


@cuda.jit
def predict(
    v_face, p, phi, normal, shear, flux, dphi, f_i, k_drag, acceleration, spacing, bc_sign, p_kind, p_bound,
    rho, mu, beta, pressure_in_solid, dt, inflow, v_star, mobility, lo, hi,
):  # fmt: skip
    nx, ny = phi.shape[0], phi.shape[1]
    for col in range(cuda.grid(1), (hi - lo) * ny, cuda.gridsize(1)):
        i, j = wrap(lo + col // ny, nx), col % ny
        predict_column(
            v_face, p, phi, normal, shear, flux, dphi, f_i, k_drag, acceleration, spacing, bc_sign, p_kind,
            p_bound, rho, mu, beta, pressure_in_solid, dt, inflow, v_star, mobility, i, j,
        )  # fmt: skip


@cuda.jit
def face_coefficients(mobility, ax, ay, az):
    columns = ax.shape[0] * ay.shape[1]  # (nx + 1) (ny + 1)
    for col in range(cuda.grid(1), columns, cuda.gridsize(1)):
        face_coefficients_column(mobility, ax, ay, az, col // ay.shape[1], col % ay.shape[1])


@cuda.jit
def pressure_rhs(v_star, phi, dphi, spacing, rho, dt, rhs):
    for col in range(cuda.grid(1), phi.shape[0] * phi.shape[1], cuda.gridsize(1)):
        pressure_rhs_column(v_star, phi, dphi, spacing, rho, dt, rhs, col // phi.shape[1], col % phi.shape[1])


@cuda.jit
def correct(v_star, eps, phi, mobility, spacing, p_kind, eps_bound, rho, beta, dt, v_face, p):
    for col in range(cuda.grid(1), phi.shape[0] * phi.shape[1], cuda.gridsize(1)):
        i, j = col // phi.shape[1], col % phi.shape[1]
        correct_column(v_star, eps, phi, mobility, spacing, p_kind, eps_bound, rho, beta, dt, v_face, p, i, j)


@cuda.jit
def cell_velocity(v_face, v_old, phi, f_i, k_drag, p_kind, v, f_exchange):
    for col in range(cuda.grid(1), phi.shape[0] * phi.shape[1], cuda.gridsize(1)):
        i, j = col // phi.shape[1], col % phi.shape[1]
        cell_velocity_column(v_face, v_old, phi, f_i, k_drag, p_kind, v, f_exchange, i, j)


@cuda.jit
def add_grid_motion(v_face, phi, edges, k_drag, bc_sign, p_kind, rho, dt, stretch, v_star):
    for col in range(cuda.grid(1), phi.shape[0] * phi.shape[1], cuda.gridsize(1)):
        i, j = col // phi.shape[1], col % phi.shape[1]
        add_grid_motion_column(v_face, phi, edges, k_drag, bc_sign, p_kind, rho, dt, stretch, v_star, i, j)


@cuda.jit
def add_grid_source(phi, dphi, rho, dt, stretch, rhs):
    for col in range(cuda.grid(1), phi.shape[0] * phi.shape[1], cuda.gridsize(1)):
        add_grid_source_column(phi, dphi, rho, dt, stretch, rhs, col // phi.shape[1], col % phi.shape[1])
