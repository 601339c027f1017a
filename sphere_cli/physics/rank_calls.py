"""The MPI functions a compiled rank loop calls (kernels/rank_messages.py), as addresses.

Numba calls a C function through an object that gives its address and signature
(numba.types.WrapperAddressProtocol): typed by its signature alone, the loop that takes it as an
argument is cached like any kernel. The functions are the MPI library's that mpi4py loaded (the
library mpiexec's ranks use: the mpich wheel, or a cluster's MPI); a handle (communicator,
datatype, operation, request) is an int in MPICH's ABI and a pointer in Open MPI's, so its type
is read from mpi4py. The buffers are passed as addresses (uintp)."""

from __future__ import annotations

import ctypes
import time
import warnings

import numba
import numba.experimental.function_type  # noqa: F401 - registers how such an object is passed and called
import numpy as np
from numba import types
from numba.extending import typeof_impl

# a C function typed by its address is what Numba calls its first-class function type, which it
# warns of as experimental when a loop taking one is compiled (typed and called as documented)
warnings.filterwarnings("ignore", message="First-class function type feature is experimental")


FUNCTIONS = ("MPI_Allreduce", "MPI_Irecv", "MPI_Isend", "MPI_Waitall")


class _CFunction(numba.types.WrapperAddressProtocol):
    """A C function of a loaded library, by name, with its Numba signature."""

    def __init__(self, library, name: str, signature):
        self._address = ctypes.cast(getattr(library, name), ctypes.c_void_p).value
        self._signature = signature
        self.numba_type = types.FunctionType(signature)

    def __wrapper_address__(self) -> int:
        return self._address

    def signature(self):
        return self._signature


@typeof_impl.register(_CFunction)
def _typeof_c_function(value: _CFunction, context) -> types.FunctionType:
    """Its type made once: Numba's own typing of such an object makes it again at every call of
    a compiled function taking it from Python (the rank loop's mpi tuple: 80 -> 42 us a call)."""
    return value.numba_type


def _handle(mpi, kind) -> tuple:
    """(Numba type, NumPy type) of an MPI handle of this kind."""
    if mpi._sizeof(kind) == ctypes.sizeof(ctypes.c_int):
        return types.int32, np.int32
    return types.intp, np.intp


def compiled_calls(world) -> tuple | None:
    """(The `mpi` argument of kernels/rank_messages.py for the ranks' communicator world.comm,
    the NumPy type of an MPI request: that of ghost_mail's requests), or None where the MPI
    functions cannot be found through the library of mpi4py's module (an mpi4py that loads its
    MPI privately): the ranks then step from Python, with mpi4py's messages."""
    mpi = world.mpi
    try:
        library = ctypes.CDLL(mpi.__file__)
        for name in FUNCTIONS:
            getattr(library, name)
    except (OSError, AttributeError):
        return None
    handle, value = _handle(mpi, mpi.Comm)
    request, _ = _handle(mpi, mpi.Request)
    i32, address = types.int32, types.uintp
    message = i32(address, i32, handle, i32, i32, handle, address)  # MPI_Isend and MPI_Irecv
    return (
        _CFunction(library, "MPI_Allreduce", i32(address, address, i32, handle, handle, handle)),
        _CFunction(library, "MPI_Irecv", message),
        _CFunction(library, "MPI_Isend", message),
        _CFunction(library, "MPI_Waitall", i32(i32, address, address)),
        _CFunction(ctypes.CDLL(None), "clock_gettime", i32(i32, address)),
        value(world.comm.handle),
        value(mpi.DOUBLE.handle),
        value(mpi.MAX.handle),
        np.int32(time.CLOCK_MONOTONIC),
        value(mpi.INT64_T.handle),
        value(mpi.SUM.handle),
    ), np.dtype(np.int32 if request == types.int32 else np.intp)


def ghost_mail(world, send: dict, receive: dict, request_type: np.dtype, width: int = 6) -> tuple:
    """The `mail` argument of kernels/rank_messages.py from a part's send and receive (rank ->
    local indices): flat, each rank's rows after the last's, in the dicts' order; `width`
    doubles a row (force and torque, and a fluid's ghost array)."""

    def flat(by_rank: dict) -> tuple:
        ranks = np.array(list(by_rank), dtype=np.int32)
        sizes = [local.size for local in by_rank.values()]
        start = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        local = np.concatenate([np.zeros(0, np.int64), *by_rank.values()]).astype(np.int64)
        return ranks, start, local, np.empty((local.size, width))

    messages = len(send) + len(receive)
    statuses = np.empty(max(messages, 1) * world.mpi._sizeof(world.mpi.Status), dtype=np.uint8)
    return (*flat(send), *flat(receive), np.empty(max(messages, 1), dtype=request_type), statuses)
