"""Packing structure (observables only): contact numbers, rattlers, solid volume in a region.

Contacts: a pair of the half neighbour list touches when its centre distance is below r_i + r_j
(minimum image), a particle touches wall w when its gap is below r_i. Rattlers: particles with
fewer than `needed` contacts carry no load in a stable packing (d + 1 = 4 for frictionless
spheres, 2 with friction); they are removed one sweep at a time, each removal lowering its
neighbours' counts, until none is left (the usual iterative definition, e.g. Silbert et al.
2002, Phys. Rev. E 65:031304).
Solid volume of sphere i inside the slab lo <= x_a <= hi: V_i times the fraction of the sphere
between two planes, from the cap volume pi h^2 (3 r - h)/3 (exact). For a box region the
fractions of the three axes are multiplied: exact for a sphere cut along one axis only, an
approximation for the few spheres on the region's edges and corners.

Arguments: pos (N,3) [m], radius (N,) [m], inv_mass (N,) [1/kg], nbr (N,C) int32 half rows,
nbr_count (N,), pairs (P,2) int64 touching pairs, length (3,) [m],
periodic (3,) uint8; wall_axis (W,) int64, wall_sign (W,), wall_coord (W,) [m].
"""

import math

from numba import njit

from ..contact_probe import pair_normal, wall_normal


@njit(cache=True)
def touching_pairs(pos, radius, nbr, nbr_count, length, periodic, pairs):
    """Fill pairs (P,2) int64 with the touching pairs of the half list; returns how many (-1 if
    pairs is too small). Serial, in row order."""
    cap = nbr.shape[1]
    count = 0
    for i in range(pos.shape[0]):
        for k in range(min(nbr_count[i], cap)):
            j = nbr[i, k]
            if pair_normal(pos, radius, i, j, length, periodic)[0]:
                if count >= pairs.shape[0]:
                    return -1
                pairs[count, 0] = i
                pairs[count, 1] = j
                count += 1
    return count


@njit(cache=True)
def contact_counts(pos, radius, inv_mass, pairs, wall_axis, wall_sign, wall_coord, count):
    """count[i] = number of particles (pairs (P,2)) and walls touching particle i (walls do not
    touch particles moved by prescription, inv_mass = 0)."""
    count[:] = 0
    for p in range(pairs.shape[0]):
        count[pairs[p, 0]] += 1
        count[pairs[p, 1]] += 1
    for i in range(pos.shape[0]):
        if inv_mass[i] == 0.0:
            continue
        for w in range(wall_axis.shape[0]):
            if wall_normal(pos, radius, i, w, wall_axis, wall_sign, wall_coord)[0]:
                count[i] += 1


@njit(cache=True)
def remove_rattlers(pairs, needed, count, alive):
    """Mark alive[i] = False for rattlers; count is lowered to the contacts among the others.
    Sweeps until nothing changes (the result does not depend on the order)."""
    alive[:] = True
    changed = True
    while changed:
        changed = False
        for i in range(count.shape[0]):
            if alive[i] and count[i] < needed:
                alive[i] = False
                changed = True
        if changed:
            for p in range(pairs.shape[0]):
                i = pairs[p, 0]
                j = pairs[p, 1]
                # a pair with one side just removed: the other loses a contact (once)
                if alive[i] != alive[j] and (count[i] >= 0 and count[j] >= 0):
                    if alive[i]:
                        count[i] -= 1
                    else:
                        count[j] -= 1
            for i in range(count.shape[0]):
                if not alive[i]:
                    count[i] = -1  # removed: its pairs no longer count


@njit(cache=True, inline="always")
def _below(h, r):
    """Volume of a sphere of radius r below a plane h above its lowest point [m^3]."""
    if h <= 0.0:
        return 0.0
    if h >= 2.0 * r:
        h = 2.0 * r
    return math.pi * h * h * (3.0 * r - h) / 3.0


@njit(cache=True, inline="always")
def slab_fraction(x, r, lo, hi):
    """Fraction of the volume of a sphere (centre x, radius r) with lo <= x' <= hi [-]."""
    whole = 4.0 / 3.0 * math.pi * r * r * r
    return (_below(hi - (x - r), r) - _below(lo - (x - r), r)) / whole


@njit(cache=True)
def region_solid_volume(pos, radius, lower, upper, cut):
    """Solid volume inside the box lower..upper [m^3]; cut (3,) uint8: axes along which the
    region is bounded (a periodic axis spanning the whole box is not cut)."""
    total = 0.0
    for i in range(pos.shape[0]):
        frac = 1.0
        for a in range(3):
            if cut[a]:
                frac *= slab_fraction(pos[i, a], radius[i], lower[a], upper[a])
        if frac > 0.0:
            total += frac * 4.0 / 3.0 * math.pi * radius[i] ** 3
    return total


@njit(cache=True)
def layer_solid_volume(pos, radius, z0, dz, out):
    """Solid volume in each horizontal layer z0 + l dz .. z0 + (l+1) dz, l < out.size [m^3]."""
    out[:] = 0.0
    layers = out.shape[0]
    for i in range(pos.shape[0]):
        r = radius[i]
        whole = 4.0 / 3.0 * math.pi * r * r * r
        first = max(0, int(math.floor((pos[i, 2] - r - z0) / dz)))
        last = min(layers - 1, int(math.floor((pos[i, 2] + r - z0) / dz)))
        for l in range(first, last + 1):
            out[l] += whole * slab_fraction(pos[i, 2], r, z0 + l * dz, z0 + (l + 1) * dz)
