"""The MPI functions a compiled rank loop calls (kernels/rank_messages.py), as addresses.

The functions are the MPI library's that mpi4py loaded (the library mpiexec's ranks use: the
mpich wheel, or a cluster's MPI), passed to the compiled loop as integers and called there by
kernels/c_calls.py call_c, so the loop is cached like any kernel. A handle (communicator,
datatype, operation, request) is an int in MPICH's ABI and a pointer in Open MPI's, so its type
is read from mpi4py. The buffers are passed as addresses (uintp)."""

from __future__ import annotations

import ctypes
import time

import numpy as np
from numba import types
from numba.core.typing.typeof import Purpose, typeof
from numba.extending import typeof_impl

FUNCTIONS = ("MPI_Allreduce", "MPI_Irecv", "MPI_Isend", "MPI_Waitall")


class Calls(tuple):
    """compiled_calls's tuple, typed once: Numba types a plain tuple element by element at every
    call of a compiled function taking it from Python."""

    def __new__(cls, values):
        calls = super().__new__(cls, values)
        calls.numba_type = types.Tuple([typeof(value, Purpose.argument) for value in calls])
        return calls


@typeof_impl.register(Calls)
def _typeof_calls(value: Calls, context) -> types.Tuple:
    return value.numba_type


def _address(library, name: str) -> np.uintp:
    return np.uintp(ctypes.cast(getattr(library, name), ctypes.c_void_p).value)


def _handle(mpi, kind) -> tuple:
    """(Numba type, a function giving the C value of mpi4py's `handle`) of an MPI handle of this
    kind. mpi4py gives a handle's bits as a Python int, sign-extended or not; MPICH's
    communicators made by MPI_Comm_dup or MPI_Comm_split have the top bit of their int set, so
    the value is the handle's low bits read as the signed C type."""
    bits = 8 * mpi._sizeof(kind)
    numba_type, numpy_type = (types.int32, np.int32) if bits == 32 else (types.intp, np.intp)

    def value(handle: int):
        handle &= (1 << bits) - 1
        return numpy_type(handle - (1 << bits) if handle >> (bits - 1) else handle)

    return numba_type, value


def compiled_calls(mpi, comm) -> tuple | None:
    """(The `mpi` argument of kernels/rank_messages.py for the mpi4py communicator comm (the
    ranks' world.comm), the NumPy type of an MPI request: that of ghost_mail's
    requests), or None where the MPI functions cannot be found through the library of mpi4py's
    module `mpi` (an mpi4py that loads its MPI privately): the ranks then step from Python, with
    mpi4py's messages."""
    try:
        library = ctypes.CDLL(mpi.__file__)
        for name in FUNCTIONS:
            getattr(library, name)
    except (OSError, AttributeError):
        return None
    _, value = _handle(mpi, mpi.Comm)
    request, _ = _handle(mpi, mpi.Request)
    calls = Calls(
        (
            *(_address(library, name) for name in FUNCTIONS),
            _address(ctypes.CDLL(None), "clock_gettime"),
            value(comm.handle),
            value(mpi.DOUBLE.handle),
            value(mpi.MAX.handle),
            np.int32(time.CLOCK_MONOTONIC),
            value(mpi.INT64_T.handle),
            value(mpi.SUM.handle),
        )
    )
    return calls, np.dtype(np.int32 if request == types.int32 else np.intp)


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
