"""Random sequential insertion of non-overlapping spheres (serial; run once at build time).

Candidates are drawn by the caller (seeded numpy), so the packing is reproducible; a grid of
cells of the largest diameter makes each overlap test O(1). Along a wrapped axis (a periodic one
the region fills) the cells wrap around and a pair's distance is the nearest image's (the
neighbour search's helpers, kernels/neighbors.py), so spheres may straddle the periodic
boundary and the packing has no seam there.
Arguments: radius (N,); cand (N, A, 3) candidate centres [m]; lower (3,), cell (scalar) [m],
ncell (3,) int64; length (3,) [m] of the region and wrap (3,) uint8, its wrapped axes; out pos
(N,3). Returns the number of particles placed.
"""

import numpy as np
from numba import njit

from .neighbors import axis_offsets, minimum_image, wrap_cell


@njit(cache=True)
def insert_random(radius, cand, lower, cell, ncell, length, wrap, pos):
    n = radius.shape[0]
    attempts = cand.shape[1]
    head = -np.ones(ncell[0] * ncell[1] * ncell[2], dtype=np.int64)
    nxt = -np.ones(n, dtype=np.int64)
    ci = np.empty(3, dtype=np.int64)
    offx = axis_offsets(ncell[0], wrap[0])
    offy = axis_offsets(ncell[1], wrap[1])
    offz = axis_offsets(ncell[2], wrap[2])
    for i in range(n):
        placed = False
        for t in range(attempts):
            c = cand[i, t]
            for a in range(3):
                ci[a] = min(max(int((c[a] - lower[a]) / cell), 0), ncell[a] - 1)
            free = True
            for ox in offx:
                gx = wrap_cell(ci[0] + ox, ncell[0], wrap[0])
                for oy in offy:
                    gy = wrap_cell(ci[1] + oy, ncell[1], wrap[1])
                    for oz in offz:
                        gz = wrap_cell(ci[2] + oz, ncell[2], wrap[2])
                        if gx < 0 or gy < 0 or gz < 0:
                            continue
                        j = head[(gx * ncell[1] + gy) * ncell[2] + gz]
                        while j >= 0 and free:
                            d2 = 0.0
                            for a in range(3):
                                d = minimum_image(c[a] - pos[j, a], length[a], wrap[a])
                                d2 += d * d
                            if d2 < (radius[i] + radius[j]) ** 2:
                                free = False
                            j = nxt[j]
            if free:
                for a in range(3):
                    pos[i, a] = c[a]
                g = (ci[0] * ncell[1] + ci[1]) * ncell[2] + ci[2]
                nxt[i] = head[g]
                head[g] = i
                placed = True
                break
        if not placed:
            return i
    return n
