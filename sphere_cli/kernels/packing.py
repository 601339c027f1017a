"""Random sequential insertion of non-overlapping spheres (serial; run once at build time).

Candidates are drawn by the caller (seeded numpy), so the packing is reproducible; a grid of
cells of the largest diameter makes each overlap test O(1). Along a wrapped axis (a periodic one
the region fills) the cells wrap around and a pair's distance is the nearest image's, so spheres
may straddle the periodic boundary and the packing has no seam there.
Arguments: radius (N,); cand (N, A, 3) candidate centres [m]; lower (3,), cell (scalar) [m],
ncell (3,) int64; length (3,) [m] of the region and wrap (3,) uint8, its wrapped axes; out pos
(N,3). Returns the number of particles placed.
"""

import numpy as np
from numba import njit


@njit(cache=True)
def _neighbour_cells(ci, ncell, wrapped, out):
    """The cells next to cell index ci along one axis (itself included), wrapped around or cut
    at the ends, each once; returns how many were written into out (3,)."""
    if wrapped and ncell >= 3:
        out[0] = (ci - 1) % ncell
        out[1] = ci
        out[2] = (ci + 1) % ncell
        return 3
    if wrapped:  # one or two cells: every one is a neighbour
        for k in range(ncell):
            out[k] = k
        return ncell
    count = 0
    for k in range(max(ci - 1, 0), min(ci + 2, ncell)):
        out[count] = k
        count += 1
    return count


@njit(cache=True)
def insert_random(radius, cand, lower, cell, ncell, length, wrap, pos):
    n = radius.shape[0]
    attempts = cand.shape[1]
    head = -np.ones(ncell[0] * ncell[1] * ncell[2], dtype=np.int64)
    nxt = -np.ones(n, dtype=np.int64)
    ci = np.empty(3, dtype=np.int64)
    near = np.empty((3, 3), dtype=np.int64)
    nears = np.empty(3, dtype=np.int64)
    for i in range(n):
        placed = False
        for t in range(attempts):
            c = cand[i, t]
            for a in range(3):
                ci[a] = min(max(int((c[a] - lower[a]) / cell), 0), ncell[a] - 1)
                nears[a] = _neighbour_cells(ci[a], ncell[a], wrap[a], near[a])
            free = True
            for kx in range(nears[0]):
                for ky in range(nears[1]):
                    for kz in range(nears[2]):
                        j = head[(near[0, kx] * ncell[1] + near[1, ky]) * ncell[2] + near[2, kz]]
                        while j >= 0 and free:
                            d2 = 0.0
                            for a in range(3):
                                d = c[a] - pos[j, a]
                                if wrap[a]:
                                    d -= length[a] * np.round(d / length[a])
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
