"""Kernels of the pore-pressure equation of the Darcy model (physics/fluid/pore_pressure.py).

Pore-pressure diffusion of the excess pressure p in a deforming granular skeleton (Goren et al.
2010, J. Geophys. Res. 115, B09216, eq. 12 with the advection of p by the solid dropped;
Damsgaard et al. 2016, Geophys. Res. Lett. 43, 12165, eq. 3), as in the original sphere:

    beta_f phi mu dp/dt = div(k grad p) - mu (dphi/dt + v_p . grad phi) / (1 - phi)

The last term is mu div(v_s): by conservation of solid mass, (dphi/dt + v_s . grad phi)/(1 - phi)
is the divergence of the solid velocity, so a compacting skeleton (phi falling along the grains'
paths) pressurises the pore fluid. Backward Euler over the fluid step dt gives the symmetric
system of physics/fluid/poisson.py

    c p' - div(k grad p') = c p - mu S,    c = beta_f phi mu / dt,  S = (dphi/dt + v_p . grad phi)/(1 - phi).

Permeability: Kozeny-Carman k = k_c phi^3 / (1 - phi)^2 per cell; the faces take the harmonic
mean of their two cells (kernels/poisson.face_means), the exact conductance of two half cells
in series.

Arguments (grid nx, ny, nz): cell fields (nx, ny, nz) float64 [p: Pa, phi: -, k: m^2,
dphi_dt: 1/s]; vector cell fields (nx, ny, nz, 3) [vbar, v: m/s, grad: Pa/m]; face arrays
ax (nx+1, ny, nz), ay (nx, ny+1, nz), az (nx, ny, nz+1) as in kernels/fluid/poisson.py [m^2];
fixed (nx, ny, nz) uint8 (1 = prescribed pressure), fixed_value (nx, ny, nz) [Pa];
ih (3,) 1/h [1/m], ih2 (3,) 1/h^2 [1/m^2]; periodic (3,) uint8.
Each kernel is a loop over the grid's columns (i, j) of a function of one column,
`<kernel>_column(..., i, j)`, which the GPU's kernels (kernels/fluid/cuda_pore_pressure.py) run a
thread a column: a column's values are the same on both. Every loop writes only its own cells
(cut_fixed_faces: zeros into its neighbours' faces too, one column after another): results do not
depend on the thread count.
"""

import math

from numba import njit, prange

# the faces' harmonic means of the permeability, a kernel of the step (physics/fluid/step_place.py)
from .poisson import face_means as face_means


@njit(cache=True, inline="always")
def clamp_porosity_column(phi, phi_min, phi_max, phi_used, i, j):
    """clamp_porosity for column (i, j); returns its number of clamped cells."""
    clamped = 0
    for k in range(phi.shape[2]):
        v = phi[i, j, k]
        if v < phi_min:
            v = phi_min
            clamped += 1
        elif v > phi_max:
            v = phi_max
            clamped += 1
        phi_used[i, j, k] = v
    return clamped


@njit(cache=True, parallel=True)
def clamp_porosity(phi, phi_min, phi_max, phi_used):
    """phi_used = phi clamped to [phi_min, phi_max]; returns the number of clamped cells."""
    nx, ny, nz = phi.shape
    clamped = 0
    for col in prange(nx * ny):
        clamped += clamp_porosity_column(phi, phi_min, phi_max, phi_used, col // ny, col % ny)
    return clamped


@njit(cache=True, inline="always")
def kozeny_carman_column(phi_used, kc, k, i, j):
    for m in range(phi_used.shape[2]):
        v = phi_used[i, j, m]
        k[i, j, m] = kc * v * v * v / ((1.0 - v) * (1.0 - v))


@njit(cache=True, parallel=True)
def kozeny_carman(phi_used, kc, k):
    """k = kc phi^3 / (1 - phi)^2 (phi already clamped below 1)."""
    nx, ny, nz = phi_used.shape
    for col in prange(nx * ny):
        kozeny_carman_column(phi_used, kc, k, col // ny, col % ny)


@njit(cache=True, inline="always")
def constant_permeability_column(value, k, i, j):
    for m in range(k.shape[2]):
        k[i, j, m] = value


@njit(cache=True, parallel=True)
def constant_permeability(value, k):
    """k = value in every cell."""
    nx, ny, nz = k.shape
    for col in prange(nx * ny):
        constant_permeability_column(value, k, col // ny, col % ny)


@njit(cache=True, inline="always")
def _derivative(f, i, j, k, axis, n, periodic, ih):
    """Central difference of a cell field along one axis; one-sided in a boundary cell of a
    non-periodic axis; 0 with a single cell."""
    if n == 1:
        return 0.0
    lo_i, lo_j, lo_k = i, j, k
    hi_i, hi_j, hi_k = i, j, k
    idx = i if axis == 0 else (j if axis == 1 else k)
    span = 2.0
    lo = idx - 1
    hi = idx + 1
    if lo < 0:
        if periodic:
            lo = n - 1
        else:
            lo = idx
            span = 1.0
    if hi > n - 1:
        if periodic:
            hi = 0
        else:
            hi = idx
            span = 1.0
    if axis == 0:
        lo_i, hi_i = lo, hi
    elif axis == 1:
        lo_j, hi_j = lo, hi
    else:
        lo_k, hi_k = lo, hi
    return (f[hi_i, hi_j, hi_k] - f[lo_i, lo_j, lo_k]) * ih / span


@njit(cache=True, inline="always")
def solid_divergence_column(phi_used, phi_raw, dphi_dt, vbar, ih, periodic, source, i, j):
    nx, ny, nz = phi_used.shape
    for k in range(nz):
        adv = vbar[i, j, k, 0] * _derivative(phi_raw, i, j, k, 0, nx, periodic[0], ih[0])
        adv += vbar[i, j, k, 1] * _derivative(phi_raw, i, j, k, 1, ny, periodic[1], ih[1])
        adv += vbar[i, j, k, 2] * _derivative(phi_raw, i, j, k, 2, nz, 0, ih[2])
        source[i, j, k] = (dphi_dt[i, j, k] + adv) / (1.0 - phi_used[i, j, k])


@njit(cache=True, parallel=True)
def solid_divergence(phi_used, phi_raw, dphi_dt, vbar, ih, periodic, source):
    """source = div v_s = (dphi/dt + vbar . grad phi) / (1 - phi) [1/s] (phi_raw, unclamped, for
    the rates, phi_used for the coefficient)."""
    nx, ny, nz = phi_used.shape
    for col in prange(nx * ny):
        solid_divergence_column(phi_used, phi_raw, dphi_dt, vbar, ih, periodic, source, col // ny, col % ny)


@njit(cache=True, inline="always")
def backward_euler_system_column(p, phi_used, source, beta, mu, dt, c, b, i, j):
    for k in range(p.shape[2]):
        ci = beta * phi_used[i, j, k] * mu / dt
        c[i, j, k] = ci
        b[i, j, k] = ci * p[i, j, k] - mu * source[i, j, k]


@njit(cache=True, parallel=True)
def backward_euler_system(p, phi_used, source, beta, mu, dt, c, b):
    """Storage c = beta phi mu / dt and right-hand side b = c p - mu source of one
    backward-Euler step."""
    nx, ny, nz = p.shape
    for col in prange(nx * ny):
        backward_euler_system_column(p, phi_used, source, beta, mu, dt, c, b, col // ny, col % ny)


@njit(cache=True, inline="always")
def eliminate_fixed_cells_column(fixed, fixed_value, ax, ay, az, ih2, periodic, c, b, i, j):
    nx, ny, nz = fixed.shape
    for k in range(nz):
        if fixed[i, j, k]:
            d = c[i, j, k]
            d += (ax[i, j, k] + ax[i + 1, j, k]) * ih2[0]
            d += (ay[i, j, k] + ay[i, j + 1, k]) * ih2[1]
            d += (az[i, j, k] + az[i, j, k + 1]) * ih2[2]
            c[i, j, k] = d
            b[i, j, k] = d * fixed_value[i, j, k]
            continue
        cc = 0.0
        bb = 0.0
        # x neighbours
        if i > 0 or periodic[0]:
            n = i - 1 if i > 0 else nx - 1
            if fixed[n, j, k]:
                w = (ax[i, j, k] if i > 0 else ax[0, j, k]) * ih2[0]
                cc += w
                bb += w * fixed_value[n, j, k]
        if i < nx - 1 or periodic[0]:
            n = i + 1 if i < nx - 1 else 0
            if fixed[n, j, k]:
                w = (ax[i + 1, j, k] if i < nx - 1 else ax[0, j, k]) * ih2[0]
                cc += w
                bb += w * fixed_value[n, j, k]
        if j > 0 or periodic[1]:
            n = j - 1 if j > 0 else ny - 1
            if fixed[i, n, k]:
                w = (ay[i, j, k] if j > 0 else ay[i, 0, k]) * ih2[1]
                cc += w
                bb += w * fixed_value[i, n, k]
        if j < ny - 1 or periodic[1]:
            n = j + 1 if j < ny - 1 else 0
            if fixed[i, n, k]:
                w = (ay[i, j + 1, k] if j < ny - 1 else ay[i, 0, k]) * ih2[1]
                cc += w
                bb += w * fixed_value[i, n, k]
        if k > 0 and fixed[i, j, k - 1]:
            w = az[i, j, k] * ih2[2]
            cc += w
            bb += w * fixed_value[i, j, k - 1]
        if k < nz - 1 and fixed[i, j, k + 1]:
            w = az[i, j, k + 1] * ih2[2]
            cc += w
            bb += w * fixed_value[i, j, k + 1]
        c[i, j, k] += cc
        b[i, j, k] += bb


@njit(cache=True, parallel=True)
def eliminate_fixed_cells(fixed, fixed_value, ax, ay, az, ih2, periodic, c, b):
    """Move the prescribed pressures out of the system: a free cell beside a fixed one gets
    a_f/h^2 on its storage and a_f/h^2 p_fixed on its right-hand side (exactly the face term
    with the neighbour known); a fixed cell gets the row d p = d p_fixed, with d its own
    diagonal, so the solution holds p_fixed exactly. Call cut_fixed_faces afterwards."""
    nx, ny, nz = fixed.shape
    for col in prange(nx * ny):
        eliminate_fixed_cells_column(fixed, fixed_value, ax, ay, az, ih2, periodic, c, b, col // ny, col % ny)


@njit(cache=True, inline="always")
def cut_fixed_faces_column(fixed, ax, ay, az, periodic, i, j):
    nx, ny, nz = fixed.shape
    for k in range(nz):
        if not fixed[i, j, k]:
            continue
        ax[i, j, k] = 0.0
        ax[i + 1, j, k] = 0.0
        ay[i, j, k] = 0.0
        ay[i, j + 1, k] = 0.0
        az[i, j, k] = 0.0
        az[i, j, k + 1] = 0.0
        if periodic[0]:
            if i == nx - 1:
                ax[0, j, k] = 0.0
            if i == 0:
                ax[nx, j, k] = 0.0
        if periodic[1]:
            if j == ny - 1:
                ay[i, 0, k] = 0.0
            if j == 0:
                ay[i, ny, k] = 0.0


@njit(cache=True)
def cut_fixed_faces(fixed, ax, ay, az, periodic):
    """Zero every face coefficient that touches a fixed cell (boundary faces included), so the
    solver sees fixed cells decoupled from the rest."""
    nx, ny, nz = fixed.shape
    for i in range(nx):
        for j in range(ny):
            cut_fixed_faces_column(fixed, ax, ay, az, periodic, i, j)


@njit(cache=True, inline="always")
def pressure_gradient_column(
    p, ih, periodic, bottom_dirichlet, top_dirichlet, bottom_value, top_value, grad, i, j
):
    nx, ny, nz = p.shape
    for k in range(nz):
        here = p[i, j, k]
        if i > 0:
            xm = p[i - 1, j, k]
        else:
            xm = p[nx - 1, j, k] if periodic[0] else here
        if i < nx - 1:
            xp = p[i + 1, j, k]
        else:
            xp = p[0, j, k] if periodic[0] else here
        if j > 0:
            ym = p[i, j - 1, k]
        else:
            ym = p[i, ny - 1, k] if periodic[1] else here
        if j < ny - 1:
            yp = p[i, j + 1, k]
        else:
            yp = p[i, 0, k] if periodic[1] else here
        if k > 0:
            zm = p[i, j, k - 1]
        else:
            zm = 2.0 * bottom_value - here if bottom_dirichlet else here
        if k < nz - 1:
            zp = p[i, j, k + 1]
        else:
            zp = 2.0 * top_value - here if top_dirichlet else here
        grad[i, j, k, 0] = 0.5 * (xp - xm) * ih[0]
        grad[i, j, k, 1] = 0.5 * (yp - ym) * ih[1]
        grad[i, j, k, 2] = 0.5 * (zp - zm) * ih[2]


@njit(cache=True, parallel=True)
def pressure_gradient(p, ih, periodic, bottom_dirichlet, top_dirichlet, bottom_value, top_value, grad):
    """Cell-centred grad p by central differences. Ghost values beyond a boundary face: the wrap
    on a periodic axis, the mirror p_ghost = p (no flow), or 2 g - p for a face held at g
    (Dirichlet), so a linear profile is differentiated exactly everywhere."""
    nx, ny, nz = p.shape
    for col in prange(nx * ny):
        pressure_gradient_column(
            p, ih, periodic, bottom_dirichlet, top_dirichlet, bottom_value, top_value, grad, col // ny,
            col % ny,
        )  # fmt: skip


@njit(cache=True, inline="always")
def darcy_velocity_column(
    p,
    ax,
    ay,
    az,
    ih,
    periodic,
    bottom_dirichlet,
    top_dirichlet,
    bottom_value,
    top_value,
    phi_used,
    mu,
    v,
    i,
    j,
):
    nx, ny, nz = p.shape
    for k in range(nz):
        here = p[i, j, k]
        s = 0.5 / (mu * phi_used[i, j, k])
        # x faces i (low) and i + 1 (high)
        lo = 0.0
        if i > 0:
            lo = -ax[i, j, k] * (here - p[i - 1, j, k]) * ih[0]
        elif periodic[0]:
            lo = -ax[0, j, k] * (here - p[nx - 1, j, k]) * ih[0]
        hi = 0.0
        if i < nx - 1:
            hi = -ax[i + 1, j, k] * (p[i + 1, j, k] - here) * ih[0]
        elif periodic[0]:
            hi = -ax[0, j, k] * (p[0, j, k] - here) * ih[0]
        v[i, j, k, 0] = s * (lo + hi)
        lo = 0.0
        if j > 0:
            lo = -ay[i, j, k] * (here - p[i, j - 1, k]) * ih[1]
        elif periodic[1]:
            lo = -ay[i, 0, k] * (here - p[i, ny - 1, k]) * ih[1]
        hi = 0.0
        if j < ny - 1:
            hi = -ay[i, j + 1, k] * (p[i, j + 1, k] - here) * ih[1]
        elif periodic[1]:
            hi = -ay[i, 0, k] * (p[i, 0, k] - here) * ih[1]
        v[i, j, k, 1] = s * (lo + hi)
        lo = 0.0
        if k > 0:
            lo = -az[i, j, k] * (here - p[i, j, k - 1]) * ih[2]
        elif bottom_dirichlet:
            lo = -az[i, j, 0] * (here - bottom_value) * 2.0 * ih[2]
        hi = 0.0
        if k < nz - 1:
            hi = -az[i, j, k + 1] * (p[i, j, k + 1] - here) * ih[2]
        elif top_dirichlet:
            hi = -az[i, j, nz] * (top_value - here) * 2.0 * ih[2]
        v[i, j, k, 2] = s * (lo + hi)


@njit(cache=True, parallel=True)
def darcy_velocity(
    p, ax, ay, az, ih, periodic, bottom_dirichlet, top_dirichlet, bottom_value, top_value, phi_used, mu, v
):
    """v = q / phi, the mean velocity of the pore fluid relative to the grains, with the Darcy
    flux q of a cell the mean of the fluxes -a_f (dp/dn)_f / mu through its two faces along
    each axis: the fluxes the solve balances (harmonic face permeabilities), so q is
    continuous across a jump of permeability where -k grad p of the cell would not be. A
    no-flow face carries 0, a face held at g the flux to g half a cell away."""
    nx, ny, nz = p.shape
    for col in prange(nx * ny):
        darcy_velocity_column(
            p, ax, ay, az, ih, periodic, bottom_dirichlet, top_dirichlet, bottom_value, top_value, phi_used,
            mu, v, col // ny, col % ny,
        )  # fmt: skip


@njit(cache=True)
def first_bad_cell(p):
    """Flat index of the first cell whose pressure is not finite, or -1."""
    flat = p.ravel()
    for m in range(flat.size):
        if not math.isfinite(flat[m]):
            return m
    return -1
