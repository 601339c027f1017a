#!/usr/bin/env bash
# The checks to run where a GPU is at hand, in one go (docs/performance.md, "The GPU"): the GPU
# tests on the device (not the simulator), then `sphere bench gpu`, dry and in a Navier-Stokes
# and a Darcy fluid, with moving walls, and the pressure solve on the GPU against the processor's
# (benchmarks/gpu_solve.py). Run from the repository root:
#
#     bash benchmarks/gpu_check.sh [SIZES [STATES]]   # 100000,1000000 and loose by default
#
# (settled beds are settled on the GPU first and cached under ~/.cache/sphere/bench: on a fresh
# machine, "loose,settled" takes minutes more).
# It uses the Python on the PATH, which needs the project's dependencies and numba-cuda (the
# CUDA extra). A machine whose image lacks pure-Python dependencies can be given their wheels in
# .whl/ (pip download --only-binary=:all: for its Python and platform): they are installed into
# a scratch directory on the path first. Results go to bench-results/ and gpu-check.log.
set -uo pipefail
cd "$(dirname "$0")/.." || exit 1
sizes=${1:-100000,1000000}
states=${2:-loose}
log=gpu-check.log
: >"$log"

site=$(mktemp -d)
if [ -d .whl ]; then
    python3 -m pip install -q --no-index --no-deps --no-compile --target "$site" .whl/*.whl
fi
# numba-cuda 0.30 overloads numpy.row_stack, which NumPy 2.5 removed (the CUDA extra pins NumPy
# below 2.5; an image that has 2.5 already gets the alias, for this check only)
printf 'import numpy\nif not hasattr(numpy, "row_stack"):\n    numpy.row_stack = numpy.vstack\n' \
    >"$site/sitecustomize.py"
export PYTHONPATH="$site${PYTHONPATH:+:$PYTHONPATH}"
export PYTHONPATH="$PWD${PYTHONPATH:+:$PYTHONPATH}" PYTHONUNBUFFERED=1 NUMBA_ENABLE_CUDASIM=0

{
    date -u
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv,noheader
    git rev-parse --short HEAD 2>/dev/null || echo "(not a git checkout)"
    python3 -m pytest -q -p no:randomly -p no:cacheprovider -W ignore \
        tests/unit/test_cuda_dem.py tests/unit/test_cuda_fluids.py
    python3 -m sphere_cli bench gpu --sizes "$sizes" --states "$states" --walls fixed,moving \
        --fluids none,navier-stokes,darcy
    python3 benchmarks/gpu_solve.py 5 32x32x64,64x64x64,128x128x128
} 2>&1 | tee -a "$log"
