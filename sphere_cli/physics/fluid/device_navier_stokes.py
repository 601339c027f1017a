"""The Navier-Stokes fluid step on a CUDA GPU (simulation.device = "cuda"): physics/fluid/
navier_stokes.py NavierStokesSolver.step with its fields at the place `FieldsOnGpu`, whose kernels
(kernels/fluid/cuda_navier_stokes.py) run the CPU's column functions a thread a grid column, and
whose pressure solve is physics/fluid/device_poisson.py's on the same device arrays. A step takes
the state's inputs up (STEP_INPUTS: velocity, pressure, porosity and its rate, the particles'
force and drag coefficient, the body acceleration) and brings its results back (STEP_OUTPUTS);
the scratch of the step (fluxes, stresses, the predicted velocity, the pressure equation) stays
on the device. The same values as the processor's, bitwise under Numba's simulator.

Imported only where a GPU is used, like every CUDA module."""

from __future__ import annotations

import types

from ...kernels.fluid import cuda_navier_stokes
from ..device_steps import launch_shape, on_gpu_or_error
from .device_fields import FieldsOnGpu
from .navier_stokes import STEP_INPUTS, STEP_OUTPUTS, NavierStokesState

KERNELS = (
    "edge_porosity", "pressure_gradient", "viscous_stresses", "advective_fluxes", "predict",
    "face_coefficients", "pressure_rhs", "correct", "cell_velocity", "add_grid_motion", "add_grid_source",
)  # fmt: skip
# the state's arrays (NavierStokesState's fields but its numbers)
ARRAYS = tuple(
    name
    for name in NavierStokesState.__dataclass_fields__
    if name not in NavierStokesState.SCALARS + NavierStokesState.MOVING_GRID
)


def step_on_gpu(solver) -> None:
    """The solver's (NavierStokesSolver's) steps on the GPU from now on, its pressure solve too."""
    from .device_poisson import on_gpu

    if isinstance(solver.on, FieldsOnGpu):
        return
    solver.poisson = on_gpu(solver.poisson)
    solver.on = on_gpu_or_error(lambda: _fields_on_gpu(solver.grid.shape))


def _fields_on_gpu(shape) -> FieldsOnGpu:
    columns = (int(shape[0]) + 1) * (int(shape[1]) + 1)  # the face arrays'
    launch = launch_shape(columns)
    kernels = types.SimpleNamespace(**{name: getattr(cuda_navier_stokes, name)[launch] for name in KERNELS})
    return FieldsOnGpu(kernels, ARRAYS, STEP_INPUTS, STEP_OUTPUTS, columns)
