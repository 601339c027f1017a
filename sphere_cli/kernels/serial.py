"""Serial twins: a parallel kernel compiled a second time without threads (prange as range),
for small scenes on one thread.

On one thread a parallel region gains nothing and still costs: about 1 us to start each, and
the per-thread buffers of a reduction, together most of a small scene's step (docs/performance.md,
"Fixed cost per step"). But compiled serially, a kernel's loops vectorise less (only a parallel
region's outlined body tells the compiler that its arrays do not alias): the kick-drift ran
2.3 x slower per particle and the pair sweep 3 x, so the pair sweep keeps its parallel kernel
and the twins run only below SERIAL_BELOW particles, where the regions cost more than the
slower loops (measured: 10 spheres 8.1 -> 4.4 us a step, 100: 10.1 -> 8.3, 300: 14.4 -> 15.5).

A twin runs the same operations in the same order as the parallel kernel does on one chunk or
many (the kernels are written so that their results do not depend on the thread count: design
guide 3), so its results are bitwise the same. It is a copy of the kernel's Python function
under another qualified name: Numba's cache files machine code by module and qualified name,
not by compile options, so a twin of the same name would overwrite the parallel kernel's entry.
`callees` gives the kernels the twin calls in place of the parallel ones (their own twins)."""

import types

import numba


def serial_twin(kernel, **callees):
    func = kernel.py_func
    scope = dict(func.__globals__)
    scope.update(callees)
    twin = types.FunctionType(func.__code__, scope, func.__name__, func.__defaults__, func.__closure__)
    twin.__qualname__ = f"{func.__qualname__}_serial"
    twin.__module__ = func.__module__
    twin.__doc__ = func.__doc__
    options = {**kernel.targetoptions, "parallel": False}
    if kernel.targetoptions.get("parallel"):
        options["error_model"] = "numpy"  # as Numba compiles a parallel loop's body
    # cached like every kernel here (caching is not among a dispatcher's target options)
    return numba.jit(**options, cache=True)(twin)


SERIAL_BELOW = 200  # particles


def use_serial(particles: int) -> bool:
    """True when the serial twins run: one thread, and a scene of fewer than SERIAL_BELOW
    particles."""
    return particles < SERIAL_BELOW and numba.get_num_threads() == 1
