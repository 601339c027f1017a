"""Kernels of the cell-centred variable-coefficient Poisson/Helmholtz system

    c_i x_i - div(a grad x)_i = b_i

on a regular grid, discretised by finite volumes with the 7-point stencil (the discrete
Laplacian of sphere-fluid-particle-interaction.md, "Fluid dynamics solution procedure", with a
coefficient on every face): (A x)_i = c_i x_i + sum over the six faces f of
a_f (x_i - x_neighbour) / h_f^2. A is symmetric; positive definite unless c = 0 everywhere
and no boundary is Dirichlet (then its null space is the constant field).

Boundaries: x and y each periodic or no-flux; z bottom and top each Dirichlet (value g given
at the boundary face, half a cell from the centre of the boundary cell: the face term is
2 a_f (x_i - g) / h_z^2, its g part moved to the right-hand side) or no-flux.

Arguments (grid nx, ny, nz):
  x, b, c, diag, inv_diag, r, z, p, q: (nx, ny, nz) float64, units of the caller's equation;
  ax (nx+1, ny, nz), ay (nx, ny+1, nz), az (nx, ny, nz+1): face coefficients a; face k along
  an axis lies between cells k-1 and k, faces 0 and n are the boundary faces. On a periodic
  axis faces 0 and n are the same face and face 0 is used;
  ih2 (3,): 1/h^2 per axis [1/m^2]; periodic_x, periodic_y, dirichlet_bottom, dirichlet_top:
  0/1; partial (nx*ny,): one partial sum per grid column (i, j), at index i*ny + j;
  lo, hi: the kernel works on the columns i in [lo, hi) only (of the coarse grid for restrict),
  reading the planes lo - 1 and hi (wrapped where periodic) as they are: the slab of one MPI
  rank, whose neighbours' planes physics/fluid/poisson.py brings in (0, nx on one rank).

Deterministic: every prange writes only its own cells and its own column's partial sum; the
partial sums are added exactly (`column_words`, kernels/exact_sum.py), so results depend
neither on the number of threads nor on how the columns are shared among MPI ranks.
"""

import math

from numba import njit, prange

from ..exact_sum import WORDS, add_exact, exact_value
from ..serial import serial_twin


@njit(cache=True, inline="always")
def _column(nx, ny, i, j, periodic_x, periodic_y):
    """The x and y neighbours of column (i, j): for each side the neighbour's index, the index of
    the face between, and 1.0, or (own index, face, 0.0) on a no-flux boundary, so that the
    stencil loop over k has no branch on x or y."""
    if i > 0:
        im, fim, wim = i - 1, i, 1.0
    elif periodic_x:
        im, fim, wim = nx - 1, 0, 1.0
    else:
        im, fim, wim = i, i, 0.0
    if i < nx - 1:
        ip, fip, wip = i + 1, i + 1, 1.0
    elif periodic_x:
        ip, fip, wip = 0, 0, 1.0
    else:
        ip, fip, wip = i, i + 1, 0.0
    if j > 0:
        jm, fjm, wjm = j - 1, j, 1.0
    elif periodic_y:
        jm, fjm, wjm = ny - 1, 0, 1.0
    else:
        jm, fjm, wjm = j, j, 0.0
    if j < ny - 1:
        jp, fjp, wjp = j + 1, j + 1, 1.0
    elif periodic_y:
        jp, fjp, wjp = 0, 0, 1.0
    else:
        jp, fjp, wjp = j, j + 1, 0.0
    return im, fim, wim, ip, fip, wip, jm, fjm, wjm, jp, fjp, wjp


@njit(cache=True, inline="always")
def _neighbour_sum(x, ax, ay, az, ih2, nb, i, j, k):
    """sum over the interior/periodic faces of cell (i,j,k) of a_f x_neighbour / h^2 (nb: the
    column's neighbours from _column)."""
    im, fim, wim, ip, fip, wip, jm, fjm, wjm, jp, fjp, wjp = nb
    s = (wim * ax[fim, j, k] * x[im, j, k] + wip * ax[fip, j, k] * x[ip, j, k]) * ih2[0]
    s += (wjm * ay[i, fjm, k] * x[i, jm, k] + wjp * ay[i, fjp, k] * x[i, jp, k]) * ih2[1]
    if k > 0:
        s += az[i, j, k] * ih2[2] * x[i, j, k - 1]
    if k < x.shape[2] - 1:
        s += az[i, j, k + 1] * ih2[2] * x[i, j, k + 1]
    return s


@njit(cache=True, parallel=True)
def prepare_system(
    b,
    c,
    ax,
    ay,
    az,
    periodic_x,
    periodic_y,
    dirichlet_bottom,
    dirichlet_top,
    bottom_value,
    top_value,
    ih2,
    rhs,
    diag,
    inv_diag,
    partial,
):
    """Diagonal of A (and its inverse), right-hand side with the Dirichlet face values moved
    over; partial = column sums of rhs^2."""
    nx, ny, nz = b.shape
    for col in prange(nx * ny):
        prepare_column(
            b, c, ax, ay, az, periodic_x, periodic_y, dirichlet_bottom, dirichlet_top, bottom_value,
            top_value, ih2, rhs, diag, inv_diag, partial, col,
        )  # fmt: skip


# Each kernel's work on one column (i, j), col = i ny + j, is a function of its own: the column's
# cells and its partial sum, what one thread does here and on a GPU (kernels/fluid/cuda_poisson.py
# runs these functions, a thread a column), so that both give the same values.


@njit(cache=True, inline="always")
def prepare_column(
    b, c, ax, ay, az, periodic_x, periodic_y, dirichlet_bottom, dirichlet_top, bottom_value, top_value, ih2,
    rhs, diag, inv_diag, partial, col,
):  # fmt: skip
    nx, ny, nz = b.shape
    i = col // ny
    j = col % ny
    acc = 0.0
    for k in range(nz):
        d = c[i, j, k]
        if i > 0 or periodic_x:
            d += ax[i, j, k] * ih2[0] if i > 0 else ax[0, j, k] * ih2[0]
        if i < nx - 1 or periodic_x:
            d += ax[i + 1, j, k] * ih2[0] if i < nx - 1 else ax[0, j, k] * ih2[0]
        if j > 0 or periodic_y:
            d += ay[i, j, k] * ih2[1] if j > 0 else ay[i, 0, k] * ih2[1]
        if j < ny - 1 or periodic_y:
            d += ay[i, j + 1, k] * ih2[1] if j < ny - 1 else ay[i, 0, k] * ih2[1]
        value = b[i, j, k]
        if k > 0:
            d += az[i, j, k] * ih2[2]
        elif dirichlet_bottom:
            w = 2.0 * az[i, j, 0] * ih2[2]
            d += w
            value += w * bottom_value
        if k < nz - 1:
            d += az[i, j, k + 1] * ih2[2]
        elif dirichlet_top:
            w = 2.0 * az[i, j, nz] * ih2[2]
            d += w
            value += w * top_value
        diag[i, j, k] = d
        inv_diag[i, j, k] = 1.0 / d if d > 0.0 else 0.0
        rhs[i, j, k] = value
        acc += value * value
    partial[col] = acc


@njit(cache=True, parallel=True)
def apply_operator(x, diag, ax, ay, az, periodic_x, periodic_y, ih2, out, partial, lo, hi):
    """out = A x; partial = column sums of x * out."""
    ny = x.shape[1]
    for c in prange((hi - lo) * ny):
        apply_column(x, diag, ax, ay, az, periodic_x, periodic_y, ih2, out, partial, lo * ny + c)


@njit(cache=True, inline="always")
def apply_column(x, diag, ax, ay, az, periodic_x, periodic_y, ih2, out, partial, col):
    nx, ny, nz = x.shape
    i = col // ny
    j = col % ny
    nb = _column(nx, ny, i, j, periodic_x, periodic_y)
    acc = 0.0
    for k in range(nz):
        v = diag[i, j, k] * x[i, j, k] - _neighbour_sum(x, ax, ay, az, ih2, nb, i, j, k)
        out[i, j, k] = v
        acc += x[i, j, k] * v
    partial[col] = acc


@njit(cache=True, parallel=True)
def residual(rhs, x, diag, ax, ay, az, periodic_x, periodic_y, ih2, r, partial, lo, hi):
    """r = rhs - A x; partial = column sums of r^2."""
    ny = x.shape[1]
    for c in prange((hi - lo) * ny):
        residual_column(rhs, x, diag, ax, ay, az, periodic_x, periodic_y, ih2, r, partial, lo * ny + c)


@njit(cache=True, inline="always")
def residual_column(rhs, x, diag, ax, ay, az, periodic_x, periodic_y, ih2, r, partial, col):
    nx, ny, nz = x.shape
    i = col // ny
    j = col % ny
    nb = _column(nx, ny, i, j, periodic_x, periodic_y)
    acc = 0.0
    for k in range(nz):
        v = rhs[i, j, k] - diag[i, j, k] * x[i, j, k]
        v += _neighbour_sum(x, ax, ay, az, ih2, nb, i, j, k)
        r[i, j, k] = v
        acc += v * v
    partial[col] = acc


@njit(cache=True)
def column_words(partial, first, last, words):
    """words (WORDS,) int64: the exact sum (kernels/exact_sum.py) of the column partial sums
    partial[first:last]."""
    for k in range(WORDS):
        words[k] = 0
    for col in range(first, last):
        add_exact(words, partial[col])


@njit(cache=True, parallel=True)
def column_sums(x, partial, lo, hi):
    ny = x.shape[1]
    for c in prange((hi - lo) * ny):
        sum_column(x, partial, lo * ny + c)


@njit(cache=True, inline="always")
def sum_column(x, partial, col):
    ny, nz = x.shape[1], x.shape[2]
    i = col // ny
    j = col % ny
    acc = 0.0
    for k in range(nz):
        acc += x[i, j, k]
    partial[col] = acc


@njit(cache=True, parallel=True)
def column_squares(x, partial, lo, hi):
    ny = x.shape[1]
    for c in prange((hi - lo) * ny):
        square_column(x, partial, lo * ny + c)


@njit(cache=True, inline="always")
def square_column(x, partial, col):
    ny, nz = x.shape[1], x.shape[2]
    i = col // ny
    j = col % ny
    acc = 0.0
    for k in range(nz):
        acc += x[i, j, k] * x[i, j, k]
    partial[col] = acc


@njit(cache=True, parallel=True)
def shift(x, amount, lo, hi):
    """x -= amount (removes the mean of a field in the singular case)."""
    ny = x.shape[1]
    for c in prange((hi - lo) * ny):
        shift_column(x, amount, lo * ny + c)


@njit(cache=True, inline="always")
def shift_column(x, amount, col):
    ny, nz = x.shape[1], x.shape[2]
    i = col // ny
    j = col % ny
    for k in range(nz):
        x[i, j, k] -= amount


@njit(cache=True, parallel=True)
def precondition(r, inv_diag, z, partial_rz, partial_z, lo, hi):
    """Jacobi preconditioner z = D^-1 r; partial_rz = column sums of r z, partial_z of z."""
    ny = r.shape[1]
    for c in prange((hi - lo) * ny):
        precondition_column(r, inv_diag, z, partial_rz, partial_z, lo * ny + c)


@njit(cache=True, inline="always")
def precondition_column(r, inv_diag, z, partial_rz, partial_z, col):
    ny, nz = r.shape[1], r.shape[2]
    i = col // ny
    j = col % ny
    rz = 0.0
    zs = 0.0
    for k in range(nz):
        v = inv_diag[i, j, k] * r[i, j, k]
        z[i, j, k] = v
        rz += r[i, j, k] * v
        zs += v
    partial_rz[col] = rz
    partial_z[col] = zs


@njit(cache=True, parallel=True)
def cg_step(x, r, p, q, alpha, inv_diag, z, partial_rr, partial_rz, partial_z, lo, hi):
    """x += alpha p; r -= alpha q; z = D^-1 r; column sums of r^2, r z and z."""
    ny = x.shape[1]
    for c in prange((hi - lo) * ny):
        cg_step_column(x, r, p, q, alpha, inv_diag, z, partial_rr, partial_rz, partial_z, lo * ny + c)


@njit(cache=True, inline="always")
def cg_step_column(x, r, p, q, alpha, inv_diag, z, partial_rr, partial_rz, partial_z, col):
    ny, nz = x.shape[1], x.shape[2]
    i = col // ny
    j = col % ny
    rr = 0.0
    rz = 0.0
    zs = 0.0
    for k in range(nz):
        x[i, j, k] += alpha * p[i, j, k]
        rv = r[i, j, k] - alpha * q[i, j, k]
        r[i, j, k] = rv
        zv = inv_diag[i, j, k] * rv
        z[i, j, k] = zv
        rr += rv * rv
        rz += rv * zv
        zs += zv
    partial_rr[col] = rr
    partial_rz[col] = rz
    partial_z[col] = zs


@njit(cache=True)
def diagonal_cg(
    x, r, p, q, z, diag, inv_diag, ax, ay, az, periodic_x, periodic_y, ih2, part_a, part_b, part_c,
    words, rz, singular, scale, tolerance, iterations, max_iterations,
):  # fmt: skip
    """The inner iterations of the diagonal-preconditioned conjugate gradient on one whole grid,
    in one call: those of physics/fluid/poisson.py PoissonSolver._pcg (the same kernels in the
    same order, the same exact sums, so the same iterates), which otherwise pay the interpreter
    about 12 us an iteration. From the search direction p and rz = r.z, until the recursive
    residual meets the tolerance (status 1), p.Ap is not positive (2) or max_iterations are done
    (0); words (WORDS,) int64 scratch. Returns (iterations, status)."""
    nx = x.shape[0]
    columns = nx * x.shape[1]
    n = x.size
    while iterations < max_iterations:
        apply_operator(p, diag, ax, ay, az, periodic_x, periodic_y, ih2, q, part_a, 0, nx)
        pq = _total(part_a, columns, words)
        if not pq > 0.0:
            return iterations, 2
        alpha = rz / pq
        cg_step(x, r, p, q, alpha, inv_diag, z, part_a, part_b, part_c, 0, nx)
        iterations += 1
        if math.sqrt(_total(part_a, columns, words)) * scale <= tolerance:
            return iterations, 1
        rz_new = _total(part_b, columns, words)
        z_mean = _total(part_c, columns, words) / n if singular else 0.0
        new_direction(p, z, rz_new / rz, z_mean, 0, nx)
        rz = rz_new
    return iterations, 0


@njit(cache=True, inline="always")
def _total(partial, columns, words):
    """The exact sum of every column's partial sum, as one rank's Slabs.sum makes it."""
    column_words(partial, 0, columns, words)
    return exact_value(words)


@njit(cache=True, parallel=True)
def new_direction(p, z, beta, z_mean, lo, hi):
    """p = (z - z_mean) + beta p (z_mean = 0 unless the system is singular: the direction then
    stays orthogonal to the constant null vector)."""
    ny = p.shape[1]
    for c in prange((hi - lo) * ny):
        direction_column(p, z, beta, z_mean, lo * ny + c)


@njit(cache=True, inline="always")
def direction_column(p, z, beta, z_mean, col):
    ny, nz = p.shape[1], p.shape[2]
    i = col // ny
    j = col % ny
    for k in range(nz):
        # beta = 0 (a restart) overwrites p without reading it
        p[i, j, k] = (z[i, j, k] - z_mean) + (beta * p[i, j, k] if beta != 0.0 else 0.0)


# one thread: the inner iterations without parallel regions (kernels/serial.py), whose start
# (about 1 us each, three an iteration) is most of an iteration on a grid of a few hundred cells
diagonal_cg_serial = serial_twin(
    diagonal_cg,
    apply_operator=serial_twin(apply_operator),
    cg_step=serial_twin(cg_step),
    new_direction=serial_twin(new_direction),
)


@njit(cache=True, parallel=True)
def jacobi_sweep(rhs, x, diag, inv_diag, ax, ay, az, periodic_x, periodic_y, ih2, x_new, partial):
    """One Jacobi iteration x_new = D^-1 (rhs + N x) (the reference's update); partial = column
    sums of the squared residual (rhs - A x)^2 of the old iterate."""
    nx, ny, nz = x.shape
    for col in prange(nx * ny):
        jacobi_sweep_column(
            rhs, x, diag, inv_diag, ax, ay, az, periodic_x, periodic_y, ih2, x_new, partial, col
        )


@njit(cache=True, inline="always")
def jacobi_sweep_column(rhs, x, diag, inv_diag, ax, ay, az, periodic_x, periodic_y, ih2, x_new, partial, col):
    nx, ny, nz = x.shape
    i = col // ny
    j = col % ny
    nb = _column(nx, ny, i, j, periodic_x, periodic_y)
    acc = 0.0
    for k in range(nz):
        s = rhs[i, j, k] + _neighbour_sum(x, ax, ay, az, ih2, nb, i, j, k)
        rv = s - diag[i, j, k] * x[i, j, k]
        acc += rv * rv
        x_new[i, j, k] = inv_diag[i, j, k] * s
    partial[col] = acc


@njit(cache=True, inline="always")
def face_means_column(cell, periodic_x, periodic_y, harmonic, ax, ay, az, i, j):
    nx, ny, nz = cell.shape
    for k in range(nz):
        here = cell[i, j, k]
        if i > 0:
            ax[i, j, k] = _mean(cell[i - 1, j, k], here, harmonic)
        else:
            other = cell[nx - 1, j, k] if periodic_x else here
            ax[0, j, k] = _mean(other, here, harmonic)
            ax[nx, j, k] = ax[0, j, k] if periodic_x else cell[nx - 1, j, k]
        if j > 0:
            ay[i, j, k] = _mean(cell[i, j - 1, k], here, harmonic)
        else:
            other = cell[i, ny - 1, k] if periodic_y else here
            ay[i, 0, k] = _mean(other, here, harmonic)
            ay[i, ny, k] = ay[i, 0, k] if periodic_y else cell[i, ny - 1, k]
        if k > 0:
            az[i, j, k] = _mean(cell[i, j, k - 1], here, harmonic)
        else:
            az[i, j, 0] = here
            az[i, j, nz] = cell[i, j, nz - 1]


@njit(cache=True, parallel=True)
def face_means(cell, periodic_x, periodic_y, harmonic, ax, ay, az):
    """Face coefficients from a cell field: the harmonic (harmonic = 1) or arithmetic mean of
    the two cells beside a face; a boundary face takes its cell's value (x/y: the wrap-around
    mean where periodic)."""
    nx, ny, nz = cell.shape
    for col in prange(nx * ny):
        face_means_column(cell, periodic_x, periodic_y, harmonic, ax, ay, az, col // ny, col % ny)


@njit(cache=True, inline="always")
def _mean(a, b, harmonic):
    if harmonic:
        s = a + b
        return 2.0 * a * b / s if s > 0.0 else 0.0
    return 0.5 * (a + b)


# -- geometric multigrid (the V-cycle preconditioner of "pcg") ------------------------------------
# Level l+1 has cells f_a times larger than level l along each axis a (f_a = 1 or 2). Restriction
# averages the f_x f_y f_z children, prolongation copies a coarse value to its children (so the
# restriction is a multiple of the transposed prolongation, and the V-cycle is symmetric).


@njit(cache=True, parallel=True)
def coarsen_coefficients(c, ax, ay, az, fx, fy, fz, cc, axc, ayc, azc):
    """Coefficients of the coarse operator, re-discretised: c and each coarse face's a are the
    means of the fine values they cover (a coarse face covers fy*fz fine x faces, and so on)."""
    mx, my = cc.shape[0], cc.shape[1]
    for col in prange(mx * my):
        coarsen_column(c, ax, ay, az, fx, fy, fz, cc, axc, ayc, azc, col)


@njit(cache=True, inline="always")
def coarsen_column(c, ax, ay, az, fx, fy, fz, cc, axc, ayc, azc, col):
    mx, my, mz = cc.shape
    ci = col // my
    cj = col % my
    for ck in range(mz):
        s = 0.0
        for i in range(ci * fx, ci * fx + fx):
            for j in range(cj * fy, cj * fy + fy):
                for k in range(ck * fz, ck * fz + fz):
                    s += c[i, j, k]
        cc[ci, cj, ck] = s / (fx * fy * fz)
        s = 0.0
        for j in range(cj * fy, cj * fy + fy):
            for k in range(ck * fz, ck * fz + fz):
                s += ax[ci * fx, j, k]
        axc[ci, cj, ck] = s / (fy * fz)
        s = 0.0
        for i in range(ci * fx, ci * fx + fx):
            for k in range(ck * fz, ck * fz + fz):
                s += ay[i, cj * fy, k]
        ayc[ci, cj, ck] = s / (fx * fz)
        s = 0.0
        for i in range(ci * fx, ci * fx + fx):
            for j in range(cj * fy, cj * fy + fy):
                s += az[i, j, ck * fz]
        azc[ci, cj, ck] = s / (fx * fy)
        if ci == mx - 1:
            s = 0.0
            for j in range(cj * fy, cj * fy + fy):
                for k in range(ck * fz, ck * fz + fz):
                    s += ax[mx * fx, j, k]
            axc[mx, cj, ck] = s / (fy * fz)
        if cj == my - 1:
            s = 0.0
            for i in range(ci * fx, ci * fx + fx):
                for k in range(ck * fz, ck * fz + fz):
                    s += ay[i, my * fy, k]
            ayc[ci, my, ck] = s / (fx * fz)
        if ck == mz - 1:
            s = 0.0
            for i in range(ci * fx, ci * fx + fx):
                for j in range(cj * fy, cj * fy + fy):
                    s += az[i, j, mz * fz]
            azc[ci, cj, mz] = s / (fx * fy)


@njit(cache=True, parallel=True)
def restrict(fine, fx, fy, fz, coarse, lo, hi):
    """coarse = mean of the children in fine."""
    my = coarse.shape[1]
    for c in prange((hi - lo) * my):
        restrict_column(fine, fx, fy, fz, coarse, lo * my + c)


@njit(cache=True, inline="always")
def restrict_column(fine, fx, fy, fz, coarse, col):
    """restrict of the coarse column col."""
    my, mz = coarse.shape[1], coarse.shape[2]
    ci = col // my
    cj = col % my
    for ck in range(mz):
        s = 0.0
        for i in range(ci * fx, ci * fx + fx):
            for j in range(cj * fy, cj * fy + fy):
                for k in range(ck * fz, ck * fz + fz):
                    s += fine[i, j, k]
        coarse[ci, cj, ck] = s / (fx * fy * fz)


@njit(cache=True, parallel=True)
def prolong_add(coarse, fx, fy, fz, fine, lo, hi):
    """fine += the coarse value of each cell's parent."""
    ny = fine.shape[1]
    for c in prange((hi - lo) * ny):
        prolong_column(coarse, fx, fy, fz, fine, lo * ny + c)


@njit(cache=True, inline="always")
def prolong_column(coarse, fx, fy, fz, fine, col):
    ny, nz = fine.shape[1], fine.shape[2]
    i = col // ny
    j = col % ny
    for k in range(nz):
        fine[i, j, k] += coarse[i // fx, j // fy, k // fz]


@njit(cache=True, parallel=True)
def jacobi_smooth(rhs, x, inv_diag, diag, ax, ay, az, periodic_x, periodic_y, ih2, omega, out, lo, hi):
    """One damped Jacobi sweep out = x + omega D^-1 (rhs - A x) (symmetric smoother)."""
    ny = x.shape[1]
    for c in prange((hi - lo) * ny):
        smooth_column(
            rhs, x, inv_diag, diag, ax, ay, az, periodic_x, periodic_y, ih2, omega, out, lo * ny + c
        )


@njit(cache=True, inline="always")
def smooth_column(rhs, x, inv_diag, diag, ax, ay, az, periodic_x, periodic_y, ih2, omega, out, col):
    nx, ny, nz = x.shape
    i = col // ny
    j = col % ny
    nb = _column(nx, ny, i, j, periodic_x, periodic_y)
    for k in range(nz):
        s = rhs[i, j, k] - diag[i, j, k] * x[i, j, k]
        s += _neighbour_sum(x, ax, ay, az, ih2, nb, i, j, k)
        out[i, j, k] = x[i, j, k] + omega * inv_diag[i, j, k] * s


@njit(cache=True)
def jacobi_smooth_pairs(rhs, x, inv_diag, diag, ax, ay, az, periodic_x, periodic_y, ih2, omega, tmp, pairs):
    """`pairs` times jacobi_smooth of the whole grid from x into tmp and back into x, in one call:
    the coarsest level's 40 sweeps spent 5 us each returning to the interpreter."""
    nx = x.shape[0]
    for _ in range(pairs):
        jacobi_smooth(rhs, x, inv_diag, diag, ax, ay, az, periodic_x, periodic_y, ih2, omega, tmp, 0, nx)
        jacobi_smooth(rhs, tmp, inv_diag, diag, ax, ay, az, periodic_x, periodic_y, ih2, omega, x, 0, nx)


@njit(cache=True, inline="always")
def _red_black_plane(rhs, x, inv_diag, ax, ay, az, periodic_x, periodic_y, ih2, color, i):
    """Gauss-Seidel in place of the cells of one colour, (i + j + k) % 2 == color, of plane i:
    x_i = (b_i + sum of a_f x_neighbour / h^2) / A_ii. Each reads cells of the other colour
    only (a periodic axis needs an even cell count for that), so the order of the updates of a
    colour, and the threads or ranks sharing them, change nothing."""
    ny = x.shape[1]
    for j in range(ny):
        red_black_column(rhs, x, inv_diag, ax, ay, az, periodic_x, periodic_y, ih2, color, i * ny + j)


@njit(cache=True, inline="always")
def red_black_column(rhs, x, inv_diag, ax, ay, az, periodic_x, periodic_y, ih2, color, col):
    """The cells of colour `color` of column col (_red_black_plane)."""
    nx, ny, nz = x.shape
    i = col // ny
    j = col % ny
    nb = _column(nx, ny, i, j, periodic_x, periodic_y)
    for k in range((i + j + color) % 2, nz, 2):
        x[i, j, k] = inv_diag[i, j, k] * (rhs[i, j, k] + _neighbour_sum(x, ax, ay, az, ih2, nb, i, j, k))


@njit(cache=True, parallel=True)
def red_black_sweep(rhs, x, inv_diag, ax, ay, az, periodic_x, periodic_y, ih2, color, lo, hi):
    """One colour of a red-black Gauss-Seidel sweep of the planes [lo, hi) (_red_black_plane),
    counted around a periodic x axis: -1 is the last plane, nx the first (a rank's slab and the
    plane either side, physics/fluid/poisson.py Slabs.extended)."""
    nx = x.shape[0]
    for t in prange(hi - lo):
        _red_black_plane(rhs, x, inv_diag, ax, ay, az, periodic_x, periodic_y, ih2, color, (lo + t) % nx)


@njit(cache=True, parallel=True)
def red_black_sweep_whole(rhs, x, inv_diag, ax, ay, az, periodic_x, periodic_y, ih2, first, blocks):
    """A whole red-black sweep of the grid, colour `first` then the other, in one pass over the
    memory instead of two: each of `blocks` runs of planes takes the first colour of plane i
    and then the second of plane i - 1, whose neighbours of the first colour are all done; the
    second colour of each run's first and last planes, whose neighbours lie in the runs beside
    it, follows when every run is through. The same values as the two colours one after the
    other (red_black_sweep), whatever `blocks`."""
    nx = x.shape[0]
    second = 1 - first
    for b in prange(blocks):
        start, end = b * nx // blocks, (b + 1) * nx // blocks
        for i in range(start, end):
            _red_black_plane(rhs, x, inv_diag, ax, ay, az, periodic_x, periodic_y, ih2, first, i)
            if start < i - 1:
                _red_black_plane(rhs, x, inv_diag, ax, ay, az, periodic_x, periodic_y, ih2, second, i - 1)
    # (one inlined copy of the plane's loops here, not two: each took about a second to compile)
    for b in prange(blocks):
        start, end = b * nx // blocks, (b + 1) * nx // blocks
        for last in range(2):  # the run's first plane, then its last if another
            if start < end - last:
                plane = end - 1 if last else start
                _red_black_plane(rhs, x, inv_diag, ax, ay, az, periodic_x, periodic_y, ih2, second, plane)


@njit(cache=True)
def red_black_smooth(rhs, x, inv_diag, ax, ay, az, periodic_x, periodic_y, ih2, first, sweeps, blocks):
    """`sweeps` red-black sweeps of the whole grid (red_black_sweep_whole) in one call."""
    for _ in range(sweeps):
        red_black_sweep_whole(rhs, x, inv_diag, ax, ay, az, periodic_x, periodic_y, ih2, first, blocks)


@njit(cache=True, parallel=True)
def column_dots(r, z, partial_rz, partial_z, lo, hi):
    """partial_rz = column sums of r z, partial_z of z."""
    ny = r.shape[1]
    for c in prange((hi - lo) * ny):
        dot_column(r, z, partial_rz, partial_z, lo * ny + c)


@njit(cache=True, inline="always")
def dot_column(r, z, partial_rz, partial_z, col):
    ny, nz = r.shape[1], r.shape[2]
    i = col // ny
    j = col % ny
    rz = 0.0
    zs = 0.0
    for k in range(nz):
        rz += r[i, j, k] * z[i, j, k]
        zs += z[i, j, k]
    partial_rz[col] = rz
    partial_z[col] = zs
