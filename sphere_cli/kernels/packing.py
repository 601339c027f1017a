"""Random sequential insertion of non-overlapping spheres (serial; run once at build time).

Candidates are drawn by the caller (seeded numpy), so the packing is reproducible; a grid of
cells of the largest diameter makes each overlap test O(1).
Arguments: radius (N,); cand (N, A, 3) candidate centres [m]; lower (3,), cell (scalar) [m],
ncell (3,) int64; out pos (N,3). Returns the number of particles placed.
"""

import numpy as np
from numba import njit


@njit(cache=True)
def insert_random(radius, cand, lower, cell, ncell, pos):
    n = radius.shape[0]
    attempts = cand.shape[1]
    head = -np.ones(ncell[0] * ncell[1] * ncell[2], dtype=np.int64)
    nxt = -np.ones(n, dtype=np.int64)
    for i in range(n):
        placed = False
        for t in range(attempts):
            c = cand[i, t]
            ci = np.empty(3, dtype=np.int64)
            for a in range(3):
                ci[a] = min(max(int((c[a] - lower[a]) / cell), 0), ncell[a] - 1)
            free = True
            for gx in range(max(ci[0] - 1, 0), min(ci[0] + 2, ncell[0])):
                for gy in range(max(ci[1] - 1, 0), min(ci[1] + 2, ncell[1])):
                    for gz in range(max(ci[2] - 1, 0), min(ci[2] + 2, ncell[2])):
                        j = head[(gx * ncell[1] + gy) * ncell[2] + gz]
                        while j >= 0 and free:
                            d2 = 0.0
                            for a in range(3):
                                d2 += (c[a] - pos[j, a]) ** 2
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
