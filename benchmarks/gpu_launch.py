"""The cost of launching each GPU kernel of one step from Python (physics/device_steps.py), three
ways: numba-cuda's plain launch, a specialized dispatcher (`kernel.specialize`), and the same
launch through cuda.core's `launch` with the arguments converted once (what numba-cuda's
private `_Kernel.launch` does at every call). Also the per-step zeroing and reading back of the
largest displacement. Needs a GPU and the CUDA extra:

    python benchmarks/gpu_launch.py [N]      # N spheres of the canonical loose bed, 1000 by default

The kernels are launched 1000 times each on a bed small enough that their own work is a few
microseconds, so the figure is the launch. The launches change the bed (it is no longer a valid
state afterwards): only the times mean anything. docs/performance.md gives the figures.
"""

import sys
import time

import numpy as np
from cuda.core import LaunchConfig, launch
from numba import cuda
from numba.cuda.cudadrv import driver

from sphere_cli.bench.dem import canonical_case, on_device
from sphere_cli.config.load import parse_case
from sphere_cli.scene.builder import build_scene
from sphere_cli.simulation import advance

REPEATS = 1000


def one_step_launches(scene) -> list:
    """(kernel, threads, arguments, block) of each launch of one step."""
    device = scene.step.compiled
    seen = []
    plain = device._launch

    def capture(kernel, size, *args, block=None):
        seen.append((kernel, size, args, block))
        plain(kernel, size, *args, block=block)

    device._launch = capture
    advance(scene, 1)
    device._launch = plain
    return seen


def microseconds(call, *args) -> float:
    """The mean time of call(*args) over REPEATS calls, the GPU's work included."""
    call(*args)
    cuda.synchronize()
    started = time.perf_counter()
    for _ in range(REPEATS):
        call(*args)
    cuda.synchronize()
    return (time.perf_counter() - started) / REPEATS * 1e6


def main(n: int) -> None:
    lid = '[[walls]]\nface = "z+"'
    text = canonical_case(n).replace(lid, lid + '\nmode = "stress"\nstress = 1000.0')
    scene = build_scene(parse_case(on_device(text, "cuda")))
    advance(scene, 5)  # compiled and on the device
    for kernel, size, args, block in one_step_launches(scene):
        threads = block or min(128, size)
        grid = -(-size // threads)
        plain = microseconds(kernel[grid, threads], *args)
        special = microseconds(kernel.specialize(*args)[grid, threads], *args)
        compiled = next(iter(kernel.overloads.values()))
        converted, written_back = [], []
        for kind, value in zip(compiled.argument_types, args, strict=True):
            compiled._prepare_args(kind, value, 0, written_back, converted)
        config = LaunchConfig(grid=(grid, 1, 1), block=(threads, 1, 1), shmem_size=0)
        function = compiled._codelibrary.get_cufunc().kernel
        stream = driver._to_core_stream(0)
        prepared = microseconds(launch, stream, config, function, *converted)
        print(
            f"{kernel.py_func.__name__:>18} ({len(args):2d} arguments): plain {plain:6.1f} us, "
            f"specialized {special:6.1f} us, arguments converted once {prepared:6.1f} us"
        )
    worst, zero = scene.step.compiled.d["worst"], np.zeros(1)

    def zeroed_and_read() -> None:
        worst.copy_to_device(zero)
        worst.copy_to_host()

    both = microseconds(zeroed_and_read)
    print(f"the largest displacement zeroed and read back: {both:.1f} us")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 1000)
