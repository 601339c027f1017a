"""A fluid model's step fields on a CUDA GPU (physics/fluid/step_place.py FieldsOnProcessor's
calls): a device array for each of its state's arrays, kernels launched there. A step takes its
inputs up and brings its outputs back; the rest (its scratch) stays on the device.

Imported only where a GPU is used, like every CUDA module."""

from __future__ import annotations

import types

import numpy as np
from numba import cuda

from ...kernels.fluid import cuda_poisson
from ..device_steps import launch_shape, on_gpu_or_error


class FieldsOnGpu:
    """kernels: the model's GPU kernels by the names of its processor's (launched, or Python
    functions launching them); arrays: the names of the state's arrays (a tuple of arrays, such
    as the face coefficients, is a tuple of device arrays); inputs and outputs: those a step reads
    from the host and writes back to it; columns: the most grid columns a kernel takes (the
    launch of `scale`)."""

    where = ", stepped on the GPU"

    def __init__(self, kernels, arrays: tuple, inputs: tuple, outputs: tuple, columns: int):
        self.kernels = kernels
        self.arrays, self.inputs, self.outputs = arrays, inputs, outputs
        self._scale = cuda_poisson.scale[launch_shape(columns)]
        self.work = None  # the device's arrays, made at the first step
        self.smalls = {}  # id of a host array -> (it, its device array): small()

    @staticmethod
    def run(step):
        """step(), a CUDA failure in it the user's error naming simulation.device (it runs in the
        fluid's own step on the host, outside DeviceSteps.run)."""
        return on_gpu_or_error(step)

    def fields(self, state):
        if self.work is None:
            self.work = types.SimpleNamespace(
                **{name: _to_device(getattr(state, name)) for name in self.arrays}
            )
            return self.work
        for name in self.inputs:
            getattr(self.work, name).copy_to_device(getattr(state, name))
        return self.work

    def results(self, work, state, names=None) -> None:
        for name in self.outputs if names is None else names:
            getattr(work, name).copy_to_host(getattr(state, name))

    def small(self, values: np.ndarray):
        """values in the device array kept for that host array (a solver's spacing and boundary
        values, the same arrays every step: copied, not allocated, at each)."""
        held = self.smalls.get(id(values))
        if held is None or held[0] is not values:
            held = self.smalls[id(values)] = (values, cuda.to_device(np.ascontiguousarray(values)))
        else:
            held[1].copy_to_device(np.ascontiguousarray(values))
        return held[1]

    def device_bytes(self) -> int:
        """The bytes of the step's fields on the device (none before its first step)."""
        arrays = [] if self.work is None else list(vars(self.work).values())
        arrays = [a for value in arrays for a in (value if isinstance(value, tuple) else (value,))]
        return sum(a.nbytes for a in (*arrays, *(held for _, held in self.smalls.values())))

    def scale(self, a, factor: float, out) -> None:
        self._scale(a.reshape(a.size), factor, out.reshape(out.size))

    @staticmethod
    def copy(destination, source) -> None:
        destination.copy_to_device(source)

    @staticmethod
    def shift_to_mean(field, mean: float) -> None:
        """As on the processor, through the host (the processor's mean of the same values)."""
        values = field.copy_to_host()
        values += mean - float(np.mean(values))
        field.copy_to_device(values)


def _to_device(value):
    if isinstance(value, tuple):
        return tuple(cuda.to_device(a) for a in value)
    return cuda.to_device(value)
