"""Serial twins: a parallel kernel compiled a second time without threads (prange as range),
which one thread runs instead of the kernel.

On one thread a parallel region gains nothing and still costs: about 1 us to start each, and
the per-thread buffers of a reduction, together most of a small scene's step (docs/performance.md,
"Fixed cost per step"). Compiled as a plain function, though, a loop lacks two things that
Numba gives a parallel region's outlined body, and without them it ran 1.5-3 x slower per
particle: freedom from reference counting (the array views and calls inside the pair sweep's
loops counted references with atomic instructions: 36 % of its time), and the promise that its
arrays do not overlap (without it the compiler keeps a loop scalar, or re-checks the overlap at
run time). Every twin is compiled without the reference-counting runtime (so a twin must not
allocate: Numba refuses to compile one that does). A twin marked `distinct` is also compiled
with every pointer argument declared not to overlap another (Numba's noalias flag, which Numba
sets itself for a parallel body whose arrays it finds unaliased). So made, the twins run as
fast per particle as the parallel kernels on one thread, or faster (docs/performance.md), and
one thread runs them at every scene size.

`distinct` is a promise the caller keeps: no array argument shares memory with another argument
that the kernel writes (empty arrays excepted: nothing is read or written through them). The
step loops, which pass the same arrays to several kernels, are twins without it; a kernel they
call keeps its own declaration, valid inside it.

A twin runs the same operations in the same order as the parallel kernel does on one chunk or
many (the kernels are written so that their results do not depend on the thread count: design
guide 3), so its results are bitwise the same. It is a copy of the kernel's Python function
under another qualified name: Numba's cache files machine code by module and qualified name,
not by compile options, so a twin of the same name would overwrite the parallel kernel's entry.
`callees` gives the kernels the twin calls in place of the parallel ones (their own twins).

The three sweeps of a step's contacts (the pair sweep, the pairs across chunks and the plane
walls: kernels/contact.py, walls.py) and the energy budget's booking (kernels/observe/
energy_budget.py book_particles) are written the other way round: the sweep of one chunk,
or of several one after the other, is a kernel compiled as a twin is (`serial_kernel`), which
one thread runs, and the parallel kernel is a prange over the chunks calling it for each (as
kernels/steps.py chunk_steps_end does). Numba's parallel passes then see a few lines rather
than the whole sweep, and the sweep compiles once for both: the first run of the demo on two
threads compiled for 39-40 s instead of 47 s (docs/performance.md, "The contacts' sweeps
compiled once for any thread count")."""

import inspect
import types

import numba
from numba.core.compiler import CompilerBase, DefaultPassBuilder


class _DistinctArrays(CompilerBase):
    """Numba's nopython pipeline with the noalias flag set: every pointer argument of the
    compiled function (the arrays' data among them) is declared not to overlap another."""

    def define_pipelines(self):
        self.state.flags.noalias = True
        return [DefaultPassBuilder.define_nopython_pipeline(self.state)]


def _copy(func, suffix: str, callees: dict):
    """The Python function `func` under its qualified name + suffix, calling `callees` (by
    name) in place of the functions of those names."""
    scope = dict(func.__globals__)
    scope.update(callees)
    twin = types.FunctionType(func.__code__, scope, func.__name__, func.__defaults__, func.__closure__)
    twin.__qualname__ = f"{func.__qualname__}_{suffix}"
    twin.__module__ = func.__module__
    twin.__doc__ = func.__doc__
    return twin


def variant(kernel, suffix: str, **callees):
    """`kernel` compiled again, with its own options, calling `callees` in place of the
    functions of those names: a compiled loop with a model's kernel in a place its own module
    leaves for it (kernels/steps.py fluid_force), so that the loop's module imports nothing of
    that model. Cached under its own qualified name, as a twin is."""
    if not hasattr(kernel, "py_func"):  # NUMBA_DISABLE_JIT: the plain function, its callees set
        return _copy(kernel, suffix, callees)
    return numba.jit(**kernel.targetoptions, cache=True)(_copy(kernel.py_func, suffix, callees))


def _serial_options(options: dict, distinct: bool) -> dict:
    """Numba's options for a kernel compiled as a twin is: without reference counting, with
    `distinct` its arrays declared not to overlap, and cached like every kernel here (caching is
    not among a dispatcher's target options)."""
    options = {**options, "_nrt": False, "cache": True}
    if distinct:
        options["pipeline_class"] = _DistinctArrays
    return options


def serial_twin(kernel, distinct: bool = False, **callees):
    if not hasattr(kernel, "py_func"):  # NUMBA_DISABLE_JIT: a plain function, threads or none
        return kernel
    twin = _copy(kernel.py_func, "serial", callees)
    options = {**kernel.targetoptions, "parallel": False}
    if kernel.targetoptions.get("parallel"):
        options["error_model"] = "numpy"  # as Numba compiles a parallel loop's body
    return numba.jit(**_serial_options(options, distinct))(twin)


def serial_kernel(distinct: bool = False):
    """Decorator: a chunk's kernel compiled as a serial twin is (no reference counting; with
    `distinct`, no array argument overlapping another, the promise `serial_twin` describes),
    which a parallel kernel calls for each of its chunks in a prange over them, and one thread
    calls for the one chunk. Its parallel caller is then a few lines for Numba's parallel passes
    rather than the whole sweep (which took them 6 to 10 s to compile a kernel), and the sweep's
    code is compiled once for any thread count."""
    options = _serial_options({"nopython": True, "error_model": "numpy"}, distinct)
    return numba.jit(**options)


def positions(kernel, *names: str) -> tuple[int, ...]:
    """Where `kernel` takes each of its parameters `names` (a tuple of its arguments is indexed by
    such constants: Numba indexes a tuple by constants only)."""
    parameters = list(inspect.signature(getattr(kernel, "py_func", kernel)).parameters)
    return tuple(parameters.index(name) for name in names)


def use_serial() -> bool:
    """True when the serial twins run: on one thread."""
    return numba.get_num_threads() == 1
