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

import numpy as np
from numba import cuda

from ...kernels.fluid import cuda_navier_stokes
from ..device_steps import launch_shape, on_gpu_or_error
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


class FieldsOnGpu:
    """A fluid step's fields on the GPU (navier_stokes.py FieldsOnProcessor's calls): a device
    array for each of the state's, kernels of one launch sized for the face arrays' columns."""

    where = ", stepped on the GPU"

    def __init__(self, shape):
        launch = launch_shape((int(shape[0]) + 1) * (int(shape[1]) + 1))  # the face arrays' columns
        self.kernels = types.SimpleNamespace(
            **{name: getattr(cuda_navier_stokes, name)[launch] for name in KERNELS}
        )
        self._scale = cuda_navier_stokes.scale[launch]
        self.work = None  # the device's arrays, made at the first step
        self.smalls = {}  # id of a host array -> (it, its device array): small()

    @staticmethod
    def run(step):
        """step(), a CUDA failure in it the user's error naming simulation.device (it runs in the
        fluid's own step on the host, outside DeviceSteps.run)."""
        return on_gpu_or_error(step)

    def fields(self, fs: NavierStokesState):
        if self.work is None:
            self.work = types.SimpleNamespace(**{name: cuda.to_device(getattr(fs, name)) for name in ARRAYS})
            return self.work
        for name in STEP_INPUTS:
            getattr(self.work, name).copy_to_device(getattr(fs, name))
        return self.work

    @staticmethod
    def results(work, fs: NavierStokesState, names=STEP_OUTPUTS) -> None:
        for name in names:
            getattr(work, name).copy_to_host(getattr(fs, name))

    def small(self, values: np.ndarray):
        """values in the device array kept for that host array (the solver's spacing and boundary
        values, the same arrays every step: copied, not allocated, at each)."""
        held = self.smalls.get(id(values))
        if held is None or held[0] is not values:
            held = self.smalls[id(values)] = (values, cuda.to_device(np.ascontiguousarray(values)))
        else:
            held[1].copy_to_device(np.ascontiguousarray(values))
        return held[1]

    def scale(self, a, factor: float, out) -> None:
        self._scale(a.reshape(a.size), factor, out.reshape(out.size))

    @staticmethod
    def copy(destination, source) -> None:
        destination.copy_to_device(source)


def step_on_gpu(solver) -> None:
    """The solver's (NavierStokesSolver's) steps on the GPU from now on, its pressure solve too."""
    from .device_poisson import on_gpu

    if isinstance(solver.on, FieldsOnGpu):
        return
    solver.poisson = on_gpu(solver.poisson)
    solver.on = on_gpu_or_error(lambda: FieldsOnGpu(solver.grid.shape))
