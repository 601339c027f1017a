"""A C function called from compiled code by its address, which the caller passes in as an integer
(physics/rank_calls.py gives the MPI library's): the compiled function holds no address of its
own, so it is cached like any kernel, and an integer argument costs its call from Python
nothing (Numba's first-class function objects, the other way to pass a C function in, took
about 35 us a call to type and unbox a tuple of five)."""

from llvmlite import ir
from numba import types
from numba.extending import intrinsic


@intrinsic
def call_c(typingctx, address, arguments):
    """The C function at `address` called with the values of the tuple `arguments`, every one an
    integer (an address as uintp, an int as int32, a handle as its C type): its int32 result.
    The C types of the parameters are the arguments' own, so they must be the function's."""
    if not isinstance(address, types.Integer) or not isinstance(arguments, types.BaseTuple):
        return None
    if not all(isinstance(kind, types.Integer) for kind in arguments):
        return None

    def call(context, builder, signature, values):
        kinds = signature.args[1]
        parameters = [context.get_value_type(kind) for kind in kinds]
        function_type = ir.FunctionType(ir.IntType(32), parameters)
        function = builder.inttoptr(values[0], function_type.as_pointer())
        return builder.call(function, [builder.extract_value(values[1], k) for k in range(len(kinds))])

    return types.int32(address, arguments), call
