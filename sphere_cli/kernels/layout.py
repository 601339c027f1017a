"""Flat views of per-particle vectors, for loops the compiler can vectorise and keep in
registers; a prefetch hint, and the hints for one particle's lines.

A (N,3) array indexed a[i, axis] costs an address computation with its run-time row stride per
array, and a signed index makes Numba emit negative-index wraparound code at every access:
either keeps a loop over particles scalar, and in the contact sweeps the strides of ten arrays
spill registers. Viewed flat, a[3 i + axis] with unsigned i shares one index between all the
arrays and has a stride the compiler knows.

The view is made by `flat`, an intrinsic that copies the array's fields into a 1-D array
structure. Numba's reshape would make the same view through a call to its C helper, after which
the compiler no longer knows that the view's memory is that of an argument the kernel declares
distinct from the others (kernels/serial.py): a serial kick-drift over 10 000 particles ran its
kick loop in 5.1 ns a particle with reshape and 2.2 ns with this view.
"""

import numpy as np
from llvmlite import ir
from numba import njit, types
from numba.core import cgutils
from numba.core.imputils import impl_ret_borrowed
from numba.extending import intrinsic
from numba.np.arrayobj import make_array, populate_array

U1 = np.uint64(1)
U2 = np.uint64(2)
U3 = np.uint64(3)


@intrinsic
def flat(typingctx, a):
    """The (N,3) C-contiguous array a as a (3N,) view: element (i, axis) is at 3 i + axis (any
    C-contiguous array as the 1-D view of its elements in order)."""
    if not (isinstance(a, types.Array) and a.layout == "C"):
        return None

    def view(context, builder, signature, arguments):
        whole = make_array(signature.args[0])(context, builder, arguments[0])
        line = make_array(signature.return_type)(context, builder)
        populate_array(
            line,
            data=whole.data,
            shape=[whole.nitems],
            strides=[whole.itemsize],
            itemsize=whole.itemsize,
            meminfo=whole.meminfo,
            parent=whole.parent,
        )
        return impl_ret_borrowed(context, builder, signature.return_type, line._getvalue())

    return a.copy(ndim=1, layout="C")(a), view


@intrinsic
def prefetch(typingctx, a, index):
    """Ask the processor to bring the cache line of a[index] (a 1-D array) into its caches,
    without waiting for it (LLVM's llvm.prefetch: a read, kept in every level): a hint that
    changes no value, for a load whose address is known well before the load."""
    if not (isinstance(a, types.Array) and a.ndim == 1 and isinstance(index, types.Integer)):
        return None

    def hint(context, builder, signature, arguments):
        array_type, index_type = signature.args
        array = make_array(array_type)(context, builder, arguments[0])
        at = context.cast(builder, arguments[1], index_type, types.intp)
        pointer = cgutils.get_item_pointer(context, builder, array_type, array, [at], wraparound=False)
        byte = ir.IntType(8).as_pointer()
        word = ir.IntType(32)
        function_type = ir.FunctionType(ir.VoidType(), [byte, word, word, word])
        function = cgutils.get_or_insert_function(builder.module, function_type, "llvm.prefetch.p0i8")
        # read (0), the most locality (3), data (1)
        builder.call(function, [builder.bitcast(pointer, byte), word(0), word(3), word(1)])
        return context.get_dummy_value()

    return types.void(a, index), hint


@njit(cache=True, inline="always")
def prefetch_particle(k, vectors, values):
    """Prefetch hints for the lines of particle k (unsigned) in the flat views of (N,3) arrays
    `vectors` and in the (N,) arrays `values` (tuples of float64 arrays): what the pair sweep and
    the wall contacts read of a particle they reach a little later (kernels/contact.py,
    kernels/walls.py)."""
    k3 = U3 * k
    for line in vectors:
        prefetch(line, k3)
    for value in values:
        prefetch(value, k)
