"""Verlet neighbour lists built from a cell list, with the contact history carried across rebuilds.

A half list: row i holds every j > i (sorted ascending) with |x_i - x_j| < r_i + r_j + skin, so
each pair is listed, and its force computed, once. The rows have a fixed capacity C; the springs
of the listed pairs are stored packed, row after row: the pair (i, nbr[i, k]) has its spring at
hist[start[i] + k], start[i] the number of pairs listed in the rows before i (a settled bed lists
~3.5 pairs in rows of ~11 slots, so the springs take a third of the memory and bandwidth of
padded rows). The reverse list gives each particle the pairs in which it is the second member:
rev[i] holds the packed index start[j] + k of every pair (j, i), j < i, with nbr[j, k] = i,
sorted by j. A force kernel can write a pair's force into the pair's own slot at that index,
and each particle then gathers its reverse slots and its own row in that fixed order
(ascending partner index), so the sums do not depend on the thread count (design guide 3).
The list stays valid until some particle has moved skin/2 since the build.

Cells: cubes of at least two largest radii plus the skin, numbered with z fastest. Where there
are few enough cells (a few per particle) every cell has its run in `cell_start`; where there
are not (a sparse scene: one small sphere in a 1 m box would need 10^11 cells), only the
occupied cells are listed, their numbers sorted in `cell_key`, and a cell's run is found by
binary search, so memory and time follow the particle count, not the box volume.

Arguments (N particles, C neighbour slots per particle, R reverse slots per particle, P listed
pairs):
  pos (N,3) [m], radius (N,) [m], lower/length (3,) box corner and edge [m],
  periodic (3,) uint8, nbr (N,C) int32, nbr_count (N,) int32, start (N+1,) int64,
  hist (>= P,3) [m] tangential springs (pair (i, nbr[i, k]) seen from i, at start[i] + k),
  rev (N,R) int32, rev_count (N,) int32.
Capacity: a row that would exceed C (or R) stores what fits and records its true count; the
caller sees count > C, grows the list and rebuilds (no contact is ever dropped silently).
"""

import math

import numpy as np
from numba import njit, prange

from .layout import U1, U2, U3, flat


@njit(cache=True, inline="always")
def minimum_image(d, length, periodic):
    if periodic and d > 0.5 * length:
        return d - length
    if periodic and d < -0.5 * length:
        return d + length
    return d


@njit(cache=True, inline="always")
def cell_number(pos, i, lower, cell_size, ncell):
    """The cell of particle i, numbered with z fastest (clamped to the grid, so escaped
    particles still bin); also the GPU's (kernels/cuda_dem.py)."""
    flat = 0
    for a in range(3):
        c = int(math.floor((pos[i, a] - lower[a]) / cell_size[a]))
        if c < 0:
            c = 0
        elif c >= ncell[a]:
            c = ncell[a] - 1
        flat = flat * ncell[a] + c
    return flat


@njit(cache=True, inline="always")
def insert_ascending(nbr, i, count, j):
    """Put j into row i of nbr, whose first `count` slots are ascending, keeping them so: a
    row sorted by j fixes the order of the force sums (also the GPU's rows, kernels/cuda_dem.py)."""
    k = count
    while k > 0 and nbr[i, k - 1] > j:
        nbr[i, k] = nbr[i, k - 1]
        k -= 1
    nbr[i, k] = j


@njit(cache=True)
def cell_index(pos, lower, cell_size, ncell, cell_of):
    """Cell of each particle (cell_number)."""
    for i in range(pos.shape[0]):
        cell_of[i] = cell_number(pos, i, lower, cell_size, ncell)


@njit(cache=True)
def counting_sort(cell_of, ncells_total, cell_start, order):
    """Particles ordered by cell (stable, so deterministic); cell c is order[start[c]:start[c+1]]."""
    cell_start[:] = 0
    for i in range(cell_of.shape[0]):
        cell_start[cell_of[i] + 1] += 1
    for c in range(ncells_total):
        cell_start[c + 1] += cell_start[c]
    fill = cell_start[:-1].copy()
    for i in range(cell_of.shape[0]):
        c = cell_of[i]
        order[fill[c]] = i
        fill[c] += 1


@njit(cache=True)
def sort_occupied(cell_of, order, cell_key, cell_start):
    """Particles ordered by cell number (stable), the occupied cells' numbers ascending in
    cell_key[:M] and cell m's particles order[cell_start[m]:cell_start[m+1]]. Returns M."""
    order[:] = np.argsort(cell_of, kind="mergesort")
    used = 0
    for s in range(order.shape[0]):
        c = cell_of[order[s]]
        if used == 0 or cell_key[used - 1] != c:
            cell_key[used] = c
            cell_start[used] = s
            used += 1
    cell_start[used] = order.shape[0]
    return used


@njit(cache=True, inline="always")
def _cell_run(cell_start, cell_key, used, first, last):
    """The part of `order` holding the cells numbered first..last: direct indices into
    cell_start when every cell is listed (used < 0), else a binary search of the occupied ones."""
    if used < 0:
        return cell_start[first], cell_start[last + 1]
    keys = cell_key[:used]
    return cell_start[np.searchsorted(keys, first)], cell_start[np.searchsorted(keys, last, side="right")]


@njit(cache=True)
def axis_offsets(n, periodic):
    """Distinct neighbouring cell offsets along one axis (fewer than 3 cells: no duplicates)."""
    if n == 1:
        return np.array([0], dtype=np.int64)
    if n == 2 and periodic:
        return np.array([0, 1], dtype=np.int64)
    return np.array([-1, 0, 1], dtype=np.int64)


@njit(cache=True, inline="always")
def wrap_cell(g, n, periodic):
    """Cell g along an axis of n cells, wrapped if periodic; -1 if it lies off the grid (also
    the GPU's, kernels/cuda_dem.py)."""
    if g < 0 or g >= n:
        if not periodic:
            return -1
        return (g + n) % n
    return g


@njit(cache=True, parallel=True)
def build_lists(
    pos,
    radius,
    length,
    periodic,
    ncell,
    cell_of,
    cell_start,
    cell_key,
    used,
    order,
    skin,
    nbr,
    nbr_count,
):
    """Fill the half rows nbr/nbr_count (their springs: carry_springs) from the cells of
    cell_index and counting_sort (every cell: used = -1) or sort_occupied (the `used` occupied
    cells numbered in cell_key) (cell_of, cell_start, order). The cells are numbered
    with z fastest, so the stencil's cells cz-1..cz+1 of each (x, y) column are one run of
    `order`: 9 runs per particle instead of 27 cells (a second run where a periodic z wraps)."""
    n = pos.shape[0]
    cap = nbr.shape[1]
    nz = ncell[2]
    offx = axis_offsets(ncell[0], periodic[0])
    offy = axis_offsets(ncell[1], periodic[1])
    x = flat(pos)
    # scalars, read once: the row stores could alias the arrays, which would be reloaded
    lx, ly, lz = length[0], length[1], length[2]
    px, py, pz = periodic[0] != 0, periodic[1] != 0, periodic[2] != 0
    for i in prange(n):
        c = cell_of[i]
        cz = c % nz
        cy = (c // nz) % ncell[1]
        cx = c // (nz * ncell[1])
        # the z cells of the stencil: [z0, z1], and [z2, z2] where a periodic axis wraps
        z0 = max(cz - 1, 0)
        z1 = min(cz + 1, nz - 1)
        z2 = -1
        if pz and nz >= 3:
            if cz == 0:
                z2 = nz - 1
            elif cz == nz - 1:
                z2 = 0
        i3 = U3 * np.uint64(i)
        xi = x[i3]
        yi = x[i3 + U1]
        zi = x[i3 + U2]
        ri = radius[i]
        count = 0
        for ox in offx:
            gx = wrap_cell(cx + ox, ncell[0], px)
            if gx < 0:
                continue
            for oy in offy:
                gy = wrap_cell(cy + oy, ncell[1], py)
                if gy < 0:
                    continue
                column = (gx * ncell[1] + gy) * nz
                for run in range(2):
                    if run == 0:
                        first, last = _cell_run(cell_start, cell_key, used, column + z0, column + z1)
                    elif z2 >= 0:
                        first, last = _cell_run(cell_start, cell_key, used, column + z2, column + z2)
                    else:
                        break
                    for s in range(first, last):
                        j = order[s]
                        if j <= i:
                            continue
                        j3 = U3 * np.uint64(j)
                        dx = minimum_image(x[j3] - xi, lx, px)
                        dy = minimum_image(x[j3 + U1] - yi, ly, py)
                        dz = minimum_image(x[j3 + U2] - zi, lz, pz)
                        reach = ri + radius[j] + skin
                        if dx * dx + dy * dy + dz * dz < reach * reach:
                            if count < cap:
                                insert_ascending(nbr, i, count, j)
                            count += 1
        nbr_count[i] = count
        # clear the unused tail, so the buffer holds nothing from older builds (checkpoints of
        # a resumed and an uninterrupted run are then equal in every slot)
        for k in range(min(count, cap), cap):
            nbr[i, k] = 0


@njit(cache=True)
def row_starts(nbr_count, cap, start):
    """start[i] = the pairs listed in the rows before i (start[N]: all of them)."""
    start[0] = 0
    for i in range(nbr_count.shape[0]):
        start[i + 1] = start[i] + min(nbr_count[i], cap)
    return start[nbr_count.shape[0]]


@njit(cache=True, parallel=True)
def carry_springs(old_nbr, old_count, old_start, old_hist, nbr, nbr_count, start, hist):
    """The springs of the new rows: a pair listed before keeps its spring, a new one starts at
    zero (both rows are sorted, so one merge per row)."""
    cap = nbr.shape[1]
    old_cap = old_nbr.shape[1]
    for i in prange(nbr.shape[0]):
        old = min(old_count[i], old_cap)
        p = 0
        for k in range(min(nbr_count[i], cap)):
            j = nbr[i, k]
            while p < old and old_nbr[i, p] < j:
                p += 1
            s = start[i] + k
            if p < old and old_nbr[i, p] == j:
                for a in range(3):
                    hist[s, a] = old_hist[old_start[i] + p, a]
            else:
                for a in range(3):
                    hist[s, a] = 0.0


@njit(cache=True, parallel=True)
def carry_springs_from_rows(gid, row_first, row_count, partner, spring, nbr, nbr_count, start, hist):
    """carry_springs from the half rows of a rank's particles by global index
    (physics/rank_steps.py): row i's partners in partner[row_first[i] :][: row_count[i]],
    ascending, their springs in spring; the new rows ascend in local index, which is global
    order."""
    cap = nbr.shape[1]
    for i in prange(nbr.shape[0]):
        p = row_first[i]
        end = p + row_count[i]
        for k in range(min(nbr_count[i], cap)):
            j = gid[nbr[i, k]]
            while p < end and partner[p] < j:
                p += 1
            s = start[i] + k
            if p < end and partner[p] == j:
                for a in range(3):
                    hist[s, a] = spring[p, a]
            else:
                for a in range(3):
                    hist[s, a] = 0.0


@njit(cache=True)
def build_reverse(nbr, nbr_count, start, rev, rev_count):
    """Fill rev/rev_count from the half rows: the packed indices start[j] + k of the pairs
    (j, i), j < i, in ascending j (a serial pass over j keeps that order). Returns the longest
    reverse row (more than R: the caller grows rev and calls again)."""
    cap = nbr.shape[1]
    rcap = rev.shape[1]
    rev_count[:] = 0
    longest = 0
    for j in range(nbr.shape[0]):
        for k in range(min(nbr_count[j], cap)):
            i = nbr[j, k]
            m = rev_count[i]
            if m < rcap:
                rev[i, m] = start[j] + k
            rev_count[i] = m + 1
            if m + 1 > longest:
                longest = m + 1
    return longest


@njit(cache=True)
def worst_overlap(pos, radius, nbr, nbr_count, length, periodic):
    """The listed pair with the largest overlap relative to the smaller radius.
    Returns (i, j, overlap / min(r_i, r_j)); (-1, -1, 0.0) when nothing touches."""
    best_i = -1
    best_j = -1
    best = 0.0
    for i in range(pos.shape[0]):
        for k in range(min(nbr_count[i], nbr.shape[1])):
            j = nbr[i, k]
            d2 = 0.0
            for a in range(3):
                d = minimum_image(pos[i, a] - pos[j, a], length[a], periodic[a])
                d2 += d * d
            overlap = (radius[i] + radius[j] - d2**0.5) / min(radius[i], radius[j])
            if overlap > best:
                best = overlap
                best_i = i
                best_j = j
    return best_i, best_j, best


@njit(cache=True, parallel=True)
def count_half_rows(full_nbr, full_count, half_count):
    """half_count[i]: the partners j > i among the first full_count[i] of full row i (the GPU's
    rows hold both members of a pair, physics/device_steps.py)."""
    for i in prange(full_nbr.shape[0]):
        m = 0
        for k in range(full_count[i]):
            if full_nbr[i, k] > i:
                m += 1
        half_count[i] = m


@njit(cache=True, parallel=True)
def fill_half_rows(full_nbr, full_count, full_hist, springs, start, half_nbr, hist):
    """The host's half rows from full rows, in their order (ascending): partners j > i into
    half_nbr, and (springs) the spring at each such full slot packed into hist from start[i]."""
    for i in prange(full_nbr.shape[0]):
        m = 0
        for k in range(full_count[i]):
            j = full_nbr[i, k]
            if j > i:
                half_nbr[i, m] = j
                if springs:
                    for a in range(3):
                        hist[start[i] + m, a] = full_hist[i, k, a]
                m += 1


@njit(cache=True)
def rows_by_global_index(idx, gid, nbr, nbr_count, start, hist, springs, row_start, partner, spring):
    """The half rows of particles idx as a rank sends them (physics/rank_steps.py): row m (of
    particle idx[m]) at row_start[m] .. row_start[m+1] of partner, each partner by its global
    index gid[j], and (springs) its spring in the same place of spring."""
    cap = nbr.shape[1]
    for m in range(idx.shape[0]):
        i = idx[m]
        first = row_start[m]
        for k in range(min(nbr_count[i], cap)):
            partner[first + k] = gid[nbr[i, k]]
            if springs:
                for a in range(3):
                    spring[first + k, a] = hist[start[i] + k, a]


@njit(cache=True)
def local_partners(gid, row_start, partner, where, count):
    """Each received partner's local index (-1 for one not held here) into where, and the
    partners held of each row into count. A row's partners ascend from above its own particle,
    as gid does: each is searched from the last one's place, in steps doubling until past it,
    then by halves (a partner is mostly a few places on)."""
    n = gid.shape[0]
    for m in range(n):
        held = 0
        lo = m + 1
        for s in range(row_start[m], row_start[m + 1]):
            step = 1
            hi = lo
            while hi < n and gid[hi] < partner[s]:
                lo = hi + 1
                hi += step
                step *= 2
            hi = min(hi, n)
            while lo < hi:
                mid = (lo + hi) // 2
                if gid[mid] < partner[s]:
                    lo = mid + 1
                else:
                    hi = mid
            if lo < n and gid[lo] == partner[s]:
                where[s] = lo
                held += 1
            else:
                where[s] = -1
        count[m] = held


@njit(cache=True)
def fill_rows(row_start, where, spring, springs, start, nbr, hist, rows):
    """The rows of a list from the received ones: received row m (row_start[m] <= s <
    row_start[m+1]) into row rows[m] of nbr, its partners held (where[s] >= 0: local_partners'
    where, or the partners themselves), in their order, and (springs) their springs packed from
    start[rows[m]]. A rank's new list takes its rows in order (rows 0, 1, ...); the lead's whole
    list each owner's row at its particle's global index (physics/rank_steps.py)."""
    for m in range(row_start.shape[0] - 1):
        i = rows[m]
        k = 0
        for s in range(row_start[m], row_start[m + 1]):
            if where[s] >= 0:
                nbr[i, k] = where[s]
                if springs:
                    for a in range(3):
                        hist[start[i] + k, a] = spring[s, a]
                k += 1


@njit(cache=True)
def drop_ghost_pairs(owned, nbr, nbr_count, start, hist, springs):
    """Leave out of a rank's rows (physics/rank_steps.py) the pairs of two particles it does not
    own, ghosts both: they add only to ghosts' forces, which the owners send. The other pairs
    keep their order and (springs) their springs; the rows are packed again from the first."""
    cap = nbr.shape[1]
    first = 0
    for i in range(nbr.shape[0]):
        was = start[i]
        kept = 0
        for k in range(min(nbr_count[i], cap)):
            j = nbr[i, k]
            if owned[i] or owned[j]:
                nbr[i, kept] = j
                if springs:  # moved towards the front only: first + kept <= was + k
                    for a in range(3):
                        hist[first + kept, a] = hist[was + k, a]
                kept += 1
        start[i] = first
        nbr_count[i] = kept
        first += kept
    start[nbr.shape[0]] = first


@njit(cache=True)
def merge_rows(kept, keep, came, source, out):
    """out[m] = kept[keep[source[m]]] where source[m] < keep.size, else came[source[m] -
    keep.size] (each (n, w)): a rank's particles after a list build, those it keeps and those
    that came, copied once."""
    for m in range(source.shape[0]):
        k = source[m]
        if k < keep.shape[0]:
            for a in range(out.shape[1]):
                out[m, a] = kept[keep[k], a]
        else:
            for a in range(out.shape[1]):
                out[m, a] = came[k - keep.shape[0], a]


@njit(cache=True)
def rows_out(source, local, box, first):
    """box[m, first : first + k] = source[local[m]] (source (n, k)): a rank's ghost message."""
    for m in range(local.shape[0]):
        for a in range(source.shape[1]):
            box[m, first + a] = source[local[m], a]


@njit(cache=True)
def rows_in(box, local, target, first):
    """target[local[m]] = box[m, first : first + k] (target (n, k)): a ghost message received."""
    for m in range(local.shape[0]):
        for a in range(target.shape[1]):
            target[local[m], a] = box[m, first + a]
