"""sphere: discrete-element simulation of dry and fluid-saturated granular materials."""

import numba

# OpenMP first: measured faster than TBB and workqueue at 2 threads (docs/performance.md).
# An explicit NUMBA_THREADING_LAYER in the environment still wins.
numba.config.THREADING_LAYER_PRIORITY = ["omp", "tbb", "workqueue"]
