"""The Darcy pore-pressure step on a CUDA GPU (simulation.device = "cuda"): physics/fluid/
pore_pressure.py PorePressure.advance with its fields at the place device_fields.py FieldsOnGpu,
whose kernels (kernels/fluid/cuda_pore_pressure.py) run the processor's column functions a thread
a grid column, and whose pressure solve is physics/fluid/device_poisson.py's on the same device
arrays. A step takes the state's inputs up (STEP_INPUTS: the pressure, the porosity, its rate and
the particles' mean velocity) and brings its results back (STEP_OUTPUTS: the pressure, the clamped
porosity, the permeability, the gradient and the Darcy velocity, which the particles' force and
the output read); the storage, the right-hand side, the skeleton's divergence and the face
coefficients stay on the device. The same values as the processor's, bitwise under Numba's
simulator.

Imported only where a GPU is used, like every CUDA module."""

from __future__ import annotations

import types

import numpy as np
from numba import cuda

from ...kernels.fluid import cuda_pore_pressure
from ..device_steps import launch_shape, on_gpu_or_error
from .device_fields import FieldsOnGpu
from .pore_pressure import STEP_INPUTS, STEP_OUTPUTS, DarcyState

KERNELS = (
    "kozeny_carman", "constant_permeability", "face_means", "solid_divergence", "backward_euler_system",
    "eliminate_fixed_cells", "cut_fixed_faces", "pressure_gradient", "darcy_velocity",
)  # fmt: skip
# the state's arrays (DarcyState's fields but its numbers)
ARRAYS = tuple(name for name in DarcyState.__dataclass_fields__ if name not in DarcyState.SCALARS)


class GpuKernels(types.SimpleNamespace):
    """kernels/fluid/pore_pressure.py's kernels by the same names and arguments, launched on the
    GPU; clamp_porosity returns its count as the processor's does (one number back)."""

    def __init__(self, launch: tuple):
        super().__init__(**{name: getattr(cuda_pore_pressure, name)[launch] for name in KERNELS})
        self._clamp = cuda_pore_pressure.clamp_porosity[launch]
        self._clamped = cuda.to_device(np.zeros(1, dtype=np.int64))

    def clamp_porosity(self, phi, phi_min: float, phi_max: float, phi_used) -> int:
        self._clamped.copy_to_device(np.zeros(1, dtype=np.int64))
        self._clamp(phi, phi_min, phi_max, phi_used, self._clamped)
        return int(self._clamped.copy_to_host()[0])


def step_on_gpu(pore) -> None:
    """The pore pressure's (PorePressure's) steps on the GPU from now on, its solve too."""
    from .device_poisson import on_gpu

    if isinstance(pore.on, FieldsOnGpu):
        return
    pore.solver = on_gpu(pore.solver)
    columns = int(pore.grid.shape[0]) * int(pore.grid.shape[1])
    pore.on = on_gpu_or_error(
        lambda: FieldsOnGpu(GpuKernels(launch_shape(columns)), ARRAYS, STEP_INPUTS, STEP_OUTPUTS, columns)
    )
