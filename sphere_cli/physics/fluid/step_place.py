"""Where a fluid model's step finds its fields: the state's own arrays and the processor's
kernels (`FieldsOnProcessor`), or their copies on a GPU and the same column functions launched
there (physics/fluid/device_fields.py FieldsOnGpu). A model's step (navier_stokes.py
NavierStokesSolver.step, pore_pressure.py PorePressure.advance) is written once against these
calls, so the two places run the same sequence of kernels on the same values."""

from __future__ import annotations

import importlib

import numpy as np


class FieldsOnProcessor:
    """The state's own arrays, and `kernels` (a module of kernels/fluid/) working on them."""

    where = ""  # for a solver's describe()

    def __init__(self, kernels):
        self.kernels = kernels

    def __reduce__(self):
        # by the module's name: a module cannot be pickled, and a solver travels (to MPI ranks,
        # to the compile-ahead helper)
        return _on_processor, (self.kernels.__name__,)

    @staticmethod
    def run(step):
        return step()

    @staticmethod
    def fields(state):
        """The state as the kernels take it, its step's inputs current (here: the state itself)."""
        return state

    @staticmethod
    def results(work, state, names=None) -> None:
        """The fields `names` (default: the step's outputs) of work into the state (here: they
        are the state's)."""

    @staticmethod
    def small(values: np.ndarray) -> np.ndarray:
        """A few numbers (spacing, boundary values) as the kernels take them."""
        return values

    @staticmethod
    def device_bytes() -> int:
        """The bytes its fields take on a GPU: none here."""
        return 0

    @staticmethod
    def scale(a, factor: float, out) -> None:
        np.multiply(a, factor, out=out)

    @staticmethod
    def copy(destination, source) -> None:
        np.copyto(destination, source)

    @staticmethod
    def shift_to_mean(field, mean: float) -> None:
        """field += mean - its mean (the one scalar added to every value)."""
        field += mean - float(np.mean(field))


def _on_processor(kernels: str) -> FieldsOnProcessor:
    return FieldsOnProcessor(importlib.import_module(kernels))
