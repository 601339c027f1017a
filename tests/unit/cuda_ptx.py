"""Compile every GPU kernel (sphere_cli/kernels/cuda_dem.py, kernels/fluid/cuda_profile_forces.py,
kernels/fluid/cuda_darcy.py, cuda_drag.py, cuda_porosity.py, cuda_poisson.py, cuda_navier_stokes.py,
cuda_pore_pressure.py, kernels/observe/cuda_energy_budget.py)
for an H200 (compute capability 9.0)
with NVIDIA's compiler, without a GPU: the simulator runs the kernels as Python and cannot tell
whether they compile. Run by tests/unit/test_cuda_dem.py with NUMBA_ENABLE_CUDASIM=0 where
numba-cuda is installed (the CUDA extra); prints each kernel's name and the fused multiply-adds in its code.

The argument types are those physics/device_steps.py and physics/fluid/device_*.py pass."""

from numba import cuda
from numba import types as t

from sphere_cli.kernels import cuda_dem
from sphere_cli.kernels.fluid import (
    cuda_darcy,
    cuda_drag,
    cuda_navier_stokes,
    cuda_poisson,
    cuda_pore_pressure,
    cuda_porosity,
    cuda_profile_forces,
)
from sphere_cli.kernels.observe import cuda_energy_budget

V = t.float64[:]  # (N,) or (3,)
M = t.float64[:, :]  # (N,3)
H = t.float64[:, :, :]  # springs (N,F,3), contact table (M,M,6)
I1, I2, L1, L2 = t.int32[:], t.int32[:, :], t.int64[:], t.int64[:, :]
L3 = t.int64[:, :, :]  # the exact sums' words (W, 3, WORDS)
H4 = t.float64[:, :, :, :]
B = t.uint8[:]  # periodic axes
F, INT, BOOL = t.float64, t.int64, t.boolean

SIGNATURES = {
    "kick_drift": (M, M, M, M, M, V, V, V, V, B, F, M, M, M, V),
    "kick": (M, M, M, M, V, V, F, V),
    "clear": (I1,),
    "bin_particles": (M, V, V, L1, L1, I1, I2, I1),
    "build_rows": (M, V, V, B, L1, L1, I1, I2, F, I2, I1, I1),
    "find_mates": (I2, I1, I2),
    "carry_springs": (I2, I1, H, I2, I1, H),
    "pair_forces": (
        M,
        M,
        M,
        M,
        M,
        V,
        V,
        V,
        I1,
        V,
        V,
        I2,
        I1,
        I2,
        H,
        H,
        BOOL,
        H,
        INT,
        BOOL,
        V,
        B,
        F,
        F,
        M,
        M,
    ),  # fmt: skip
    "find_unstable": (M, M, M, V, V, V, B, F, L1),
    "wall_forces": (M, M, M, M, M, V, V, V, V, I1, L1, V, V, M, M, H, H, BOOL, INT, BOOL, F, F, M, M, B, H),
    "wall_motion_drift": (L1, V, L2, M, V, M, M, M, M, F, L1, L1, M),
    "push_sums": (H, INT, B, L3),
    "wall_motion_kick": (L3, B, L1, L1, M, V, V, M, M, L1, V, V, V, V, V, L2, M, M, M, F, F),
}

# the fluids' forces (kernels/fluid/cuda_profile_forces.py, kernels/fluid/cuda_darcy.py)
VANS_SIGNATURES = {
    "profile_forces": (M, M, V, B, V, V, V, V, BOOL, F, F, F, F, F, V, BOOL, F, BOOL, M, M, V, V),
}
DARCY_SIGNATURES = {
    "pressure_forces": (M, V, H4, H, t.uint8, V, V, B, F, V, M),
    "push_wall": (V, INT, F, F, F, F, F, M),
}
# the Navier-Stokes drag (kernels/fluid/cuda_drag.py)
DRAG_SIGNATURES = {
    "drag_forces": (
        M,
        V,
        V,
        L1,
        B,
        M,
        INT,
        F,
        F,
        F,
        BOOL,
        L1,
        M,
        V,
        V,
        M,
        V,
        M,
        F,
        V,
        V,
        M,
        H,
        M,
        M,
        V,
        M,
        L1,
    ),  # fmt: skip
    "cell_coefficients": (I1, I1, V, I1, V),
    "exchange": (I1, I1, M, V, V, M, M, V, M, M, BOOL, F, F, H, M, V, M, M, V),
    "drag_kick": (M, M, M, V, V, L1, M, V, M, F, M, M, M, H, V, F, M, M, M, F, F, V),
}
# the porosity and the sort of particles by fluid cell (kernels/fluid/cuda_porosity.py)
POROSITY_SIGNATURES = {
    "bin_in_fluid_cells": (M, V, V, L1, B, L1, M, I1, I1),
    "count_in_cells": (L1, I1),
    "cell_starts": (I1, I1, I1),
    "fill_cells": (L1, I1, I1),
    "sort_cells": (I1, I1, I1),
    "sample_cells": (M, M, V, V, V, L1, B, F, F, L1, I1, I1, BOOL, H, H4, H, I1),
}
# the pressure solve (kernels/fluid/cuda_poisson.py; U: the boundary flags, np.uint8)
U = t.uint8
POISSON_SIGNATURES = {
    "prepare_system": (H, H, H, H, H, U, U, U, U, F, F, V, H, H, H, V),
    "apply_operator": (H, H, H, H, H, U, U, V, H, V, INT, INT),
    "residual": (H, H, H, H, H, H, U, U, V, H, V, INT, INT),
    "column_sums": (H, V, INT, INT),
    "column_squares": (H, V, INT, INT),
    "shift": (H, F, INT, INT),
    "precondition": (H, H, H, V, V, INT, INT),
    "cg_step": (H, H, H, H, F, H, H, V, V, V, INT, INT),
    "new_direction": (H, H, F, F, INT, INT),
    "jacobi_sweep": (H, H, H, H, H, H, H, U, U, V, H, V),
    "coarsen_coefficients": (H, H, H, H, INT, INT, INT, H, H, H, H),
    "restrict": (H, INT, INT, INT, H, INT, INT),
    "prolong_add": (H, INT, INT, INT, H, INT, INT),
    "jacobi_smooth": (H, H, H, H, H, H, H, U, U, V, F, H, INT, INT),
    "jacobi_smooth_pairs": (H, H, H, H, H, H, H, U, U, V, F, H, INT),
    "red_black_sweep": (H, H, H, H, H, H, U, U, V, INT, INT, INT),
    "column_dots": (H, H, V, V, INT, INT),
    "fill": (H, F),
    "scale": (V, F, V),
    "add_words": (V, INT, INT, L1),
    "clear_words": (L1,),
}
# the Navier-Stokes step (kernels/fluid/cuda_navier_stokes.py; H5: the advective fluxes)
H5 = t.float64[:, :, :, :, :]
NAVIER_STOKES_SIGNATURES = {
    "edge_porosity": (H, H4),
    "pressure_gradient": (H, V, L1, V, H4),
    "viscous_stresses": (H4, H, H4, V, M, H4, H4, INT, INT),
    "advective_fluxes": (H4, H, H4, M, H5, INT, INT),
    "predict": (H4, H, H, H4, H4, H5, H, H4, H, H4, V, M, L1, V, F, F, F, BOOL, F, V, H4, H4, INT, INT),
    "face_coefficients": (H4, H, H, H),
    "pressure_rhs": (H4, H, H, V, F, F, H),
    "correct": (H4, H, H, H4, V, L1, V, F, F, F, H4, H),
    "cell_velocity": (H4, H4, H, H4, H, L1, H4, H4),
    "add_grid_motion": (H4, H, H4, H, M, L1, F, F, F, H4),
    "add_grid_source": (H, H, F, F, F, H),
}
# the Darcy step (kernels/fluid/cuda_pore_pressure.py; U3: the fixed cells' mask)
U3 = t.uint8[:, :, :]
PORE_PRESSURE_SIGNATURES = {
    "clamp_porosity": (H, F, F, H, L1),
    "kozeny_carman": (H, F, H),
    "constant_permeability": (F, H),
    "face_means": (H, U, U, INT, H, H, H),
    "solid_divergence": (H, H, H, H4, V, B, H),
    "backward_euler_system": (H, H, H, F, F, F, H, H),
    "eliminate_fixed_cells": (U3, H, H, H, H, V, B, H, H),
    "cut_fixed_faces": (U3, H, H, H, B),
    "pressure_gradient": (H, V, B, U, U, F, F, H4),
    "darcy_velocity": (H, H, H, H, V, B, U, U, F, F, H, F, H4),
}
# the energy budget (kernels/observe/cuda_energy_budget.py)
BUDGET_SIGNATURES = {
    "book": (
        M,
        M,
        M,
        M,
        M,
        M,
        M,
        V,
        V,
        V,
        V,
        V,
        I1,
        I2,
        I1,
        H,
        BOOL,
        H,
        INT,
        BOOL,
        V,
        V,
        B,
        L1,
        V,
        V,
        M,
        M,
        M,
        H,
        H,
        BOOL,
        F,
        H,
        M,
        V,
    ),  # fmt: skip
}

if __name__ == "__main__":
    for module, signatures in (
        (cuda_dem, SIGNATURES),
        (cuda_profile_forces, VANS_SIGNATURES),
        (cuda_darcy, DARCY_SIGNATURES),
        (cuda_drag, DRAG_SIGNATURES),
        (cuda_porosity, POROSITY_SIGNATURES),
        (cuda_poisson, POISSON_SIGNATURES),
        (cuda_navier_stokes, NAVIER_STOKES_SIGNATURES),
        (cuda_pore_pressure, PORE_PRESSURE_SIGNATURES),
        (cuda_energy_budget, BUDGET_SIGNATURES),
    ):
        for name, signature in signatures.items():
            ptx, _ = cuda.compile_ptx(getattr(module, name).py_func, signature, cc=(9, 0))
            print(name, ptx.count("fma.rn.f64"))
