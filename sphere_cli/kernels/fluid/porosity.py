"""Porosity of the fluid cells from the particles (sphere-fluid-particle-interaction.md,
"Porosity estimation").

Each cell i samples the solid in a sphere of radius R centred on the cell centre (R = half the
smallest cell edge, the reference's choice): V_s,i = sum over particles j of the exact volume
common to that sphere and particle j (`lens_volume`), and phi_i = 1 - V_s,i / (4/3 pi R^3). A
cell longer along an axis than 2R is cut along it into equal parts (subdivisions (3,) int64,
the edge over 2R rounded; physics/fluid/porosity.py sampling_parts), each sampled by such a
sphere at its centre, V_s,i their sum over parts x 4/3 pi R^3: one sphere sees only the middle
of an elongated cell.
A lens volume is a continuous function of the centre distance, so phi is continuous in time as
particles move. The same lens volumes weight the per-cell mean particle velocity and diameter.

Gather form: the particles are binned into the grid cells once per call (`bin_particles`, then
a stable counting sort), and a prange over cells visits the bins within reach of its sampling
sphere in a fixed order, so the sums do not depend on the number of threads. Along a periodic
axis the bins are visited by unwrapped index, each unwrapped bin standing for one periodic
image, so every image of a particle within reach is counted once, whatever the cell count.

Arguments (N particles, grid nx, ny, nz):
  pos, wrapped (N,3) [m] centres as given and brought into the box along periodic axes;
  vel (N,3) [m/s], radius (N,) [m]; origin, spacing (3,) [m]; shape (3,) int64;
  periodic (3,) uint8; bin_of (N,) int64 flat cell index (i*ny + j)*nz + k of each particle;
  cell_start (nx*ny*nz+1,) int64, order (N,) int64 (kernels/neighbors.counting_sort);
  reach (3,) int64 bins searched on either side; porosity, mean_diameter (nx,ny,nz) [-, m];
  mean_velocity (nx,ny,nz,3) [m/s].
"""

import math

import numpy as np
from numba import njit, prange

from ..serial import serial_twin

# d^2 beyond (R + r)^2 by this factor: d >= R + r whatever the rounding of the square, its root
# and the sum (each half an ulp, 1e-16), so the particle adds exactly nothing (lens_volume's 0)
BEYOND_ROUNDING = 1.0 + 1e-12


@njit(cache=True, inline="always")
def lens_volume(big_r, r, d):
    """Volume common to two spheres of radii big_r and r whose centres are d apart [m^3]:
    0 apart, the smaller sphere when one contains the other, otherwise the lens
    pi (R + r - d)^2 (d^2 + 2 d r - 3 r^2 + 2 d R + 6 r R - 3 R^2) / (12 d)."""
    if d >= big_r + r:
        return 0.0
    if d <= abs(big_r - r):
        small = min(big_r, r)
        return 4.0 / 3.0 * math.pi * small * small * small
    gap = big_r + r - d
    return (
        math.pi
        * gap
        * gap
        * (d * d + 2.0 * d * r - 3.0 * r * r + 2.0 * d * big_r + 6.0 * r * big_r - 3.0 * big_r * big_r)
        / (12.0 * d)
    )


@njit(cache=True, inline="always")
def _wrapped(x, lower, length, periodic):
    """A coordinate brought into [lower, lower + length) along a periodic axis."""
    if periodic:
        return x - math.floor((x - lower) / length) * length
    return x


@njit(cache=True, parallel=True)
def bin_particles(pos, origin, spacing, shape, periodic, bin_of, wrapped):
    """Flat index of the cell holding each particle centre (periodic axes wrapped, others
    clamped to the grid, so a particle outside a bounded axis takes the nearest cell), and the
    centre brought into the box along the periodic axes (wrapped (N,3) [m])."""
    for p in prange(pos.shape[0]):
        bin_particle(p, pos, origin, spacing, shape, periodic, bin_of, wrapped)


@njit(cache=True, inline="always")
def bin_particle(p, pos, origin, spacing, shape, periodic, bin_of, wrapped):
    """bin_particles for particle p (also the GPU's, kernels/fluid/cuda_drag.py)."""
    flat = 0
    for a in range(3):
        length = spacing[a] * shape[a]
        x = _wrapped(pos[p, a], origin[a], length, periodic[a])
        wrapped[p, a] = x
        c = int(math.floor((x - origin[a]) / spacing[a]))
        if c < 0:
            c = 0
        elif c >= shape[a]:
            c = shape[a] - 1
        flat = flat * shape[a] + c
    bin_of[p] = flat


# one thread (the Navier-Stokes drag's loop, kernels/fluid/drag.py drag_steps_serial): without a
# parallel region (kernels/serial.py); its arrays are the particles', the drag's and the grid's own
bin_particles_serial = serial_twin(bin_particles, distinct=True)


@njit(cache=True, inline="always")
def _image(u, n):
    """(cell, image) of the unwrapped cell index u along an axis of n cells: u = cell + image n."""
    image = 0
    while u < 0:
        u += n
        image -= 1
    while u >= n:
        u -= n
        image += 1
    return u, image


@njit(cache=True, inline="always")
def _gap(centre, u, lower, width):
    """Distance [m] along an axis from a cell centre to the bin of unwrapped index u, from
    lower + u width to one width above. (The end bin of a bounded axis also holds the particles
    beyond the grid, bin_particle, but those lie farther out, on its side away from the centre.)"""
    return max(lower + u * width - centre, centre - (lower + (u + 1) * width), 0.0)


# a call of its own (which LLVM may still inline): inlined by Numba in each of sample_cell's
# four places, the kernel took 12.7 s to compile against 6.9 s, and ran no faster
@njit(cache=True)
def _add_particles(first, last, order, wrapped, vel, radius, sx, sy, sz, cx, cy, cz, big_r, want_means, sums):
    """sums (solid, three velocity moments, diameter moment) with the lens volumes of the
    particles order[first:last], shifted by the image (sx, sy, sz), added."""
    solid, m0, m1, m2, md = sums
    for s in range(first, last):
        p = order[s]
        dx = wrapped[p, 0] + sx - cx
        dy = wrapped[p, 1] + sy - cy
        dz = wrapped[p, 2] + sz - cz
        d2 = dx * dx + dy * dy + dz * dz
        touch = big_r + radius[p]
        if d2 > touch * touch * BEYOND_ROUNDING:  # surely apart: lens_volume's 0, without its root
            continue
        v = lens_volume(big_r, radius[p], math.sqrt(d2))
        if v > 0.0:
            solid += v
            if want_means:
                m0 += v * vel[p, 0]
                m1 += v * vel[p, 1]
                m2 += v * vel[p, 2]
                md += v * 2.0 * radius[p]
    return solid, m0, m1, m2, md


@njit(cache=True, inline="always")
def _bins(
    i, j, k, cx, cy, cz, wrapped, vel, radius, origin, spacing, shape, periodic, big_r, wide2, trim, reach,
    cell_start, order, want_means,
):  # fmt: skip
    """The sums of sample_cell over the bins about cell (i, j, k) centred at (cx, cy, cz) [m],
    those farther than sqrt(wide2) [m] skipped where `trim`."""
    nx, ny, nz = shape[0], shape[1], shape[2]
    lx, ly, lz = spacing[0] * nx, spacing[1] * ny, spacing[2] * nz
    sums = (0.0, 0.0, 0.0, 0.0, 0.0)
    for ux in range(i - reach[0], i + reach[0] + 1):
        gx, ix = _image(ux, nx)
        if ix != 0 and not periodic[0]:
            continue
        gap_x = _gap(cx, ux, origin[0], spacing[0]) if trim else 0.0
        for uy in range(j - reach[1], j + reach[1] + 1):
            gy, iy = _image(uy, ny)
            if iy != 0 and not periodic[1]:
                continue
            gap_y = _gap(cy, uy, origin[1], spacing[1]) if trim else 0.0
            across = gap_x * gap_x + gap_y * gap_y
            if trim and across > wide2:
                continue
            column = (gx * ny + gy) * nz
            if periodic[2]:
                for uz in range(k - reach[2], k + reach[2] + 1):
                    gap_z = _gap(cz, uz, origin[2], spacing[2]) if trim else 0.0
                    if trim and across + gap_z * gap_z > wide2:
                        continue
                    gz, iz = _image(uz, nz)
                    g = column + gz
                    sums = _add_particles(
                        cell_start[g], cell_start[g + 1], order, wrapped, vel, radius,
                        ix * lx, iy * ly, iz * lz, cx, cy, cz, big_r, want_means, sums,
                    )  # fmt: skip
            else:
                # the bins of a bounded z range are contiguous in the sorted order; those within
                # reach of the sphere are a run about k
                lo = max(k - reach[2], 0)
                hi = min(k + reach[2], nz - 1)
                while trim and lo < k and across + _gap(cz, lo, origin[2], spacing[2]) ** 2 > wide2:
                    lo += 1
                while trim and hi > k and across + _gap(cz, hi, origin[2], spacing[2]) ** 2 > wide2:
                    hi -= 1
                first, last = cell_start[column + lo], cell_start[column + hi + 1]
                if first < last:  # (most columns about a cell above a bed hold none: no call)
                    sums = _add_particles(
                        first, last, order, wrapped, vel, radius, ix * lx, iy * ly, 0.0, cx, cy, cz, big_r,
                        want_means, sums,
                    )  # fmt: skip
    return sums


@njit(cache=True, parallel=True)
def sample_cells(
    wrapped,
    vel,
    radius,
    origin,
    spacing,
    shape,
    periodic,
    sampling_radius,
    subdivisions,
    largest,
    reach,
    cell_start,
    order,
    want_means,
    porosity,
    mean_velocity,
    mean_diameter,
    first,
    last,
):
    """phi = 1 - V_s / V_c per cell of the flat cells first .. last - 1 (one MPI rank's slab of
    x planes; all of them on one rank), clamped to [0, 1] (below 0 only where particles overlap);
    with want_means also the lens-volume-weighted mean particle velocity and diameter (0 where no
    particle reaches the sampling sphere). Returns the number of those cells clamped."""
    clamped = 0
    ny, nz = shape[1], shape[2]
    # by columns of cells along z (first and last bound whole x planes): a division a column to
    # find (i, j), not three a cell (one thread, 16 000 beads in the lowest 12 of 80 mm under 32 x
    # 32 x 64 cells: 4.35 -> 3.40 ms a call with the test of BEYOND_ROUNDING, 1.73 -> 1.15 empty)
    for c in prange((last - first) // nz):
        column = first // nz + np.int64(c)  # the prange index is unsigned
        i, j = column // ny, column % ny
        for k in range(nz):
            clamped += sample_at(
                i, j, k, wrapped, vel, radius, origin, spacing, shape, periodic, sampling_radius,
                subdivisions, largest, reach, cell_start, order, want_means, porosity, mean_velocity,
                mean_diameter,
            )  # fmt: skip
    return clamped


@njit(cache=True, inline="always")
def sample_cell(
    cell, wrapped, vel, radius, origin, spacing, shape, periodic, sampling_radius, subdivisions, largest,
    reach, cell_start, order, want_means, porosity, mean_velocity, mean_diameter,
):  # fmt: skip
    """sample_cells for one cell (also the GPU's, kernels/fluid/cuda_porosity.py): 1 if its
    porosity was clamped at 0, else 0."""
    ny, nz = shape[1], shape[2]
    return sample_at(
        cell // (ny * nz), (cell // nz) % ny, cell % nz, wrapped, vel, radius, origin, spacing, shape,
        periodic, sampling_radius, subdivisions, largest, reach, cell_start, order, want_means, porosity,
        mean_velocity, mean_diameter,
    )  # fmt: skip


@njit(cache=True, inline="always")
def sample_at(
    i, j, k, wrapped, vel, radius, origin, spacing, shape, periodic, sampling_radius, subdivisions, largest,
    reach, cell_start, order, want_means, porosity, mean_velocity, mean_diameter,
):  # fmt: skip
    """sample_cell for the cell (i, j, k): in each of its subdivisions[0] x [1] x [2] equal
    parts a sphere of radius sampling_radius centred on the part (one for a cubic cell; module
    docstring)."""
    big_r = sampling_radius
    parts = subdivisions[0] * subdivisions[1] * subdivisions[2]
    sample_volume = parts * 4.0 / 3.0 * math.pi * big_r * big_r * big_r
    # a bin farther from the centre than the sampling radius and the largest particle radius
    # holds no particle that reaches the sphere (its lens volume is exactly 0, never added): it
    # is skipped, so the sums are those of every bin, bit for bit. Widened by a relative 1e-9
    # for the rounding of the binning. Where even the corner bins of the reach are nearer (cells
    # narrow against the particles), no distance is worked out.
    wide2 = ((big_r + largest) * (1.0 + 1e-9)) ** 2
    corner2 = 0.0
    for a in range(3):
        far = max(reach[a] - 0.5, 0.0) * spacing[a]
        corner2 += far * far
    trim = corner2 > wide2
    sums = (0.0, 0.0, 0.0, 0.0, 0.0)
    for part in range(parts):
        mx = part // (subdivisions[1] * subdivisions[2])
        my = (part // subdivisions[2]) % subdivisions[1]
        mz = part % subdivisions[2]
        cx = origin[0] + (i + (mx + 0.5) / subdivisions[0]) * spacing[0]
        cy = origin[1] + (j + (my + 0.5) / subdivisions[1]) * spacing[1]
        cz = origin[2] + (k + (mz + 0.5) / subdivisions[2]) * spacing[2]
        if trim:  # one loop for each, so that the narrow cells' loop does no test at all
            part_sums = _bins(
                i, j, k, cx, cy, cz, wrapped, vel, radius, origin, spacing, shape, periodic, big_r, wide2,
                True, reach, cell_start, order, want_means,
            )  # fmt: skip
        else:
            part_sums = _bins(
                i, j, k, cx, cy, cz, wrapped, vel, radius, origin, spacing, shape, periodic, big_r, wide2,
                False, reach, cell_start, order, want_means,
            )  # fmt: skip
        sums = (
            sums[0] + part_sums[0], sums[1] + part_sums[1], sums[2] + part_sums[2], sums[3] + part_sums[3],
            sums[4] + part_sums[4],
        )  # fmt: skip
    phi = 1.0 - sums[0] / sample_volume
    clamped = 0
    if phi < 0.0:
        phi = 0.0
        clamped = 1
    porosity[i, j, k] = phi
    if want_means:
        w = 1.0 / sums[0] if sums[0] > 0.0 else 0.0
        mean_velocity[i, j, k, 0] = sums[1] * w
        mean_velocity[i, j, k, 1] = sums[2] * w
        mean_velocity[i, j, k, 2] = sums[3] * w
        mean_diameter[i, j, k] = sums[4] * w
    return clamped


@njit(cache=True, parallel=True)
def rate_in_grains_frame(fixed_rate, cell_rate, mean_velocity, top_speed, shift_velocity, grid_frame):
    """On a grid whose top moved at top_speed [m/s] over the fluid step (its cell centres at
    w = top_speed (k + 1/2)/nz), cell_rate (nx,ny,nz) [1/s], the rate of the lens estimate of
    the cells moving with the grid, becomes in place the rate in a frame moving with the grains:
    (1 - a) fixed_rate + a cell_rate, fixed_rate the rate at points fixed in space and
    a = mean_velocity_z / w clipped to [0, 1] (1 everywhere with grid_frame). The lens estimate
    follows the solid's volume change best where its sampling sphere moves with the grains (a
    bed at rest under a moving grid: a = 0; a bed the grid compresses with it: a = 1). With
    shift_velocity, the mean velocity's z component becomes relative to that frame (less a w),
    as the advection of the porosity in that frame takes it."""
    nx, ny, nz = cell_rate.shape
    for ii in prange(nx):
        i = np.int64(ii)
        for j in range(ny):
            for k in range(nz):
                w = top_speed * (k + 0.5) / nz
                a = 1.0
                if not grid_frame:
                    a = min(max(mean_velocity[i, j, k, 2] / w, 0.0), 1.0) if w != 0.0 else 0.0
                cell_rate[i, j, k] = (1.0 - a) * fixed_rate[i, j, k] + a * cell_rate[i, j, k]
                if shift_velocity:
                    mean_velocity[i, j, k, 2] -= a * w
