"""Porous (volume-averaged) Navier-Stokes on a regular cell-centred grid, by operator splitting
(Langtangen et al. 2002, as in the documentation of the original sphere: Damsgaard et al. 2015,
The Cryosphere 9:2183).

Momentum, with porosity phi, fluid density rho, viscosity mu and the interaction force f_i the
fluid exerts on the particles per unit volume (the fluid receives -f_i):
  d(phi v)/dt + div(phi v v) = -(phi or 1)/rho grad p + div(phi tau)/rho - f_i/rho + phi g,
  tau = mu (grad v + grad v^T);  pressure factor phi in formulation A (pressure in both phases,
  Zhu et al. 2007 model A), 1 in formulation B (pressure in the fluid only).
Continuity: d phi/dt + div(phi v) = 0.

One fluid step of length dt:
1. predictor  v* = v + dt [-beta (1 or 1/phi)/rho grad p + div(phi tau)/(rho phi)
                            - div(phi v v)/phi + g - f_i/(rho phi)] - v dphi dt/phi,
   with the drag's change over the step, k_drag (v* - v), implicit (see `predict`);
2. pressure equation for eps = p_new - beta p from continuity with face fluxes phi_f v_f:
     A:  v = v* - dt/rho grad eps          ->  div(phi_f grad eps) = rho/dt (div(phi_f v*_f) + dphi)
     B:  v = v* - dt/(rho phi) grad eps    ->  div(grad eps)       = rho/dt (div(phi_f v*_f) + dphi)
   (the reference's B derivation drops a derivative of 1/phi and gains a spurious grad(phi).grad(eps)
   term; done exactly, B's operator has constant coefficients); with implicit drag both carry the
   factor D = 1/(1 + dt k_drag/(rho phi)) (see `predict`): faces a_f = mean(phi D) or mean(D);
3. correction v = v* - dt/rho (1 or 1/phi) D grad eps, p = beta p + eps.

Space: second-order central differences; viscous stress compact (3-point) in each direction;
the cross terms of grad v^T with the 4-point mixed stencil. Advection div(phi v v_c) in flux form,
second order and bounded: through each face the flux phi_f u_f (means of the two cells) carries
the value of v_c reconstructed from the upwind cell U with a limited slope (MUSCL, van Leer 1979,
J. Comput. Phys. 32, 101; van Leer's limiter psi(r) = (r + |r|)/(1 + r), Sweby 1984, SIAM J.
Numer. Anal. 21, 995; Versteeg & Malalasekera 2007, sec. 5.10):
  v_f = v_U + 0.5 L(v_U - v_UU, v_D - v_U),  L(a, b) = 2ab/(a + b) if ab > 0, else 0,
UU the cell upwind of U, D the cell across the face; at an extremum L = 0 (first-order upwind).
With forward Euler this is TVD (no new extrema) for sum |u_i| dt/dx_i <= 1/2: the update of a
cell is a convex combination of it and its upwind neighbours when the coefficient of each
difference, C_i (1 + psi/2 - psi/(2r)) <= 2 C_i (psi <= 2 and psi/r >= 0), sums to at most 1
(Harten 1983, J. Comput. Phys. 49, 357); first-order upwind allowed 1.
x and y are periodic. In z the cells k < 0 and k >= nz are ghosts, mirrors of the cells inside:
velocity ghost k = -1 - m (bottom) or nz + m (top) = sign * v of cell m from that boundary (bc_sign
(2,3): row 0 bottom, row 1 top; -1 for the normal component at a no-flow wall and the tangential
ones at a no-slip wall, +1 otherwise; the advection reads two ghost layers, the other terms one);
porosity ghost = boundary cell; pressure ghost 2 p_b - p_0 at a prescribed-pressure face, linear
extrapolation 2 p_0 - p_1 at a no-flow face (so a hydrostatic pressure has its exact gradient in
every cell).

Moving grid (`[fluid.grid] follow_top_wall`): the grid's top is the top wall at height H(t)
above the bottom, and its nz layers stretch uniformly, so the face k (k = 0 .. nz) moves with
w_k = k dz H'/H and a cell's volume V = dx dy dz changes at dV/dt = dx dy (w_(k+1) - w_k): the
geometric conservation law (Thomas & Lombard 1979, AIAA J. 17) holds exactly on every step.
Fields belong to the moving cells (arbitrary Lagrangian-Eulerian form, Hirt et al. 1974, J.
Comput. Phys. 14): over a cell moving with the faces, continuity and momentum are
  (1/V) d(phi V)/dt|_cell + div(phi (v - w)) = 0,
  (1/V) d(phi V v)/dt|_cell + div(phi v (v - w)) = (forces as above),
the time derivative being the backward difference of the cell's own values (dphi from the
porosity measured on the new cells, fs.porosity_rate). With the step's stretch rate s = (H_new - H_old)
/ (H_new dt) [1/s] (dz is the new height / nz), (V_new - V_old)/(V_new dt) = s and w_k =
k dz s exactly, so that:
  pressure source   dphi + phi_old s - s (phi_(k+1/2) (k+1) - phi_(k-1/2) k),   phi_old = phi - dt dphi
                    (the last term is the grid's flux div_z(phi_f w_f); `add_grid_source`);
  predictor rate    + s (phi_(k+1/2) (k+1) v_(k+1/2) - phi_(k-1/2) k v_(k-1/2)) / phi - s v
                    (v_f upwind of the flux relative to the faces, -w: first order;
                    `add_grid_motion`, with the implicit drag's factor D).
A uniform phi and v stay so (both pairs of terms cancel); summed over a column, the pore volume
sum(phi V) changes by exactly the relative flux phi_f (v_f - H') through the top face, which must
then be open (prescribed pressure; the bottom face does not move). These kernels run only on a
moving grid, after `predict` and `pressure_rhs`: a fixed grid runs exactly what it ran before.

Arguments: v, v_star, f_i, f_exchange, grad_p (nx,ny,nz,3) [m/s, N/m^3, Pa/m]; p, eps, phi,
dphi, k_drag, rhs, mobility (nx,ny,nz) [Pa, -, 1/s, kg/(m^3 s), Pa/m^2, -]; spacing (3,) [m]; gravity (3,)
[m/s^2]; bc_sign (2,3) float64; p_kind (2,) int64, 1 = prescribed pressure, 0 = no flow;
p_bound (2,) [Pa] boundary pressure (bottom, top); rho [kg/m^3]; mu [Pa s]; beta [-];
pressure_in_solid 1 for formulation A, 0 for B; dt [s] the fluid step; stretch [1/s] the
moving grid's s.
"""

import math

import numpy as np
from numba import njit, prange


# Not inline="always": Numba's IR inlining of this index wrap, reached through every other helper
# at some hundred call sites, was most of the module's compile time (predict and pressure_rhs:
# 75 s -> 24 s on the loaded 2-core machine); LLVM still inlines it, the run time is unchanged.
# Each call site of an inlined helper costs compile time: _advection has one per face.
@njit(cache=True)
def _wrap(i, n):
    if i < 0:
        return i + n
    if i >= n:
        return i - n
    return i


@njit(cache=True, inline="always")
def _shift(i, j, k, a, s):
    """The cell s (= +1 or -1) steps from (i,j,k) along axis a (not wrapped)."""
    if a == 0:
        return i + s, j, k
    if a == 1:
        return i, j + s, k
    return i, j, k + s


@njit(cache=True, inline="always")
def _vel(v, i, j, k, c, bc_sign):
    """v[i,j,k,c], periodic in x and y (i, j at most one period outside), z ghost cells mirrored:
    k = -1 - m and nz + m are sign * v of cell m from the boundary (clamped to the column)."""
    nz = v.shape[2]
    i = _wrap(i, v.shape[0])
    j = _wrap(j, v.shape[1])
    if k < 0:
        return bc_sign[0, c] * v[i, j, min(-1 - k, nz - 1), c]
    if k >= nz:
        return bc_sign[1, c] * v[i, j, max(2 * nz - 1 - k, 0), c]
    return v[i, j, k, c]


@njit(cache=True, inline="always")
def _cell(f, i, j, k):
    """f[i,j,k], periodic in x and y, the boundary cell's value in the z ghost cells."""
    nz = f.shape[2]
    k = 0 if k < 0 else (nz - 1 if k >= nz else k)
    return f[_wrap(i, f.shape[0]), _wrap(j, f.shape[1]), k]


@njit(cache=True, inline="always")
def _pres(p, i, j, k, p_kind, p_bound):
    """p[i,j,k] with the z ghost cells of a pressure (see the module docstring)."""
    nz = p.shape[2]
    i = _wrap(i, p.shape[0])
    j = _wrap(j, p.shape[1])
    if k < 0:
        if p_kind[0] == 1:
            return 2.0 * p_bound[0] - p[i, j, 0]
        return 2.0 * p[i, j, 0] - p[i, j, 1]
    if k >= nz:
        if p_kind[1] == 1:
            return 2.0 * p_bound[1] - p[i, j, nz - 1]
        return 2.0 * p[i, j, nz - 1] - p[i, j, nz - 2]
    return p[i, j, k]


@njit(cache=True, inline="always")
def _grad(p, i, j, k, a, spacing, p_kind, p_bound):
    """Central difference of p along axis a at cell (i,j,k)."""
    i1, j1, k1 = _shift(i, j, k, a, 1)
    i0, j0, k0 = _shift(i, j, k, a, -1)
    return (_pres(p, i1, j1, k1, p_kind, p_bound) - _pres(p, i0, j0, k0, p_kind, p_bound)) / (
        2.0 * spacing[a]
    )


@njit(cache=True, parallel=True)
def pressure_gradient(p, spacing, p_kind, p_bound, grad_p):
    """grad_p = central-difference gradient of p in every cell [Pa/m]."""
    nx, ny, nz = p.shape
    for ii in prange(nx):
        i = np.int64(ii)  # the prange index is unsigned: i - 1 must not wrap
        for j in range(ny):
            for k in range(nz):
                for a in range(3):
                    grad_p[i, j, k, a] = _grad(p, i, j, k, a, spacing, p_kind, p_bound)


@njit(cache=True, inline="always")
def _viscous(v, phi, i, j, k, c, spacing, bc_sign):
    """div(phi (grad v + grad v^T))_c / viscosity: compact 3-point second differences for
    d_a(phi d_a v_c) and d_c(phi d_c v_c), the 4-point mixed stencil for d_a(phi d_c v_a), a != c."""
    ph = phi[i, j, k]
    vc = v[i, j, k, c]
    total = 0.0
    for a in range(3):
        i1, j1, k1 = _shift(i, j, k, a, 1)
        i0, j0, k0 = _shift(i, j, k, a, -1)
        phi_up = 0.5 * (ph + _cell(phi, i1, j1, k1))
        phi_dn = 0.5 * (ph + _cell(phi, i0, j0, k0))
        second = (
            phi_up * (_vel(v, i1, j1, k1, c, bc_sign) - vc) - phi_dn * (vc - _vel(v, i0, j0, k0, c, bc_sign))
        ) / (spacing[a] * spacing[a])
        if a == c:
            total += 2.0 * second
        else:
            # d_a(phi d_c v_a), d_c v_a centred at the two neighbours along a
            ia, ja, ka = _shift(i1, j1, k1, c, 1)
            ib, jb, kb = _shift(i1, j1, k1, c, -1)
            up = _cell(phi, i1, j1, k1) * (_vel(v, ia, ja, ka, a, bc_sign) - _vel(v, ib, jb, kb, a, bc_sign))
            ia, ja, ka = _shift(i0, j0, k0, c, 1)
            ib, jb, kb = _shift(i0, j0, k0, c, -1)
            dn = _cell(phi, i0, j0, k0) * (_vel(v, ia, ja, ka, a, bc_sign) - _vel(v, ib, jb, kb, a, bc_sign))
            total += second + (up - dn) / (4.0 * spacing[a] * spacing[c])
    return total


@njit(cache=True, inline="always")
def _limited_face_value(upwind_upwind, upwind, downwind):
    """v_U + 0.5 L(v_U - v_UU, v_D - v_U): the face value reconstructed from the upwind cell with
    van Leer's limited slope L(a, b) = 2ab/(a + b), 0 unless a and b have the same sign."""
    back = upwind - upwind_upwind
    ahead = downwind - upwind
    product = back * ahead
    if product > 0.0:
        return upwind + product / (back + ahead)
    return upwind


@njit(cache=True, inline="always")
def _far(i, j, k, a, s, shape):
    """The cell two steps s (= +1 or -1) from (i,j,k) along axis a, wrapped in x and y so that
    _vel's single wrap suffices even on a grid one cell wide (z is left to _vel's mirror)."""
    if a == 0:
        return _wrap(_wrap(i + 2 * s, shape[0]), shape[0]), j, k
    if a == 1:
        return i, _wrap(_wrap(j + 2 * s, shape[1]), shape[1]), k
    return i, j, k + 2 * s


@njit(cache=True, inline="always")
def _advection(v, phi, i, j, k, c, spacing, bc_sign):
    """div(phi v v_c): face fluxes phi_f u_f carrying the limited upwind-biased value of v_c (see
    the module docstring); the five cells W2, W, P, E, E2 along each axis."""
    ph = phi[i, j, k]
    vc = v[i, j, k, c]
    total = 0.0
    for a in range(3):
        i1, j1, k1 = _shift(i, j, k, a, 1)
        i0, j0, k0 = _shift(i, j, k, a, -1)
        i2, j2, k2 = _far(i, j, k, a, 1, v.shape)
        im, jm, km = _far(i, j, k, a, -1, v.shape)
        va = v[i, j, k, a]
        flux_up = 0.25 * (ph + _cell(phi, i1, j1, k1)) * (va + _vel(v, i1, j1, k1, a, bc_sign))
        flux_dn = 0.25 * (ph + _cell(phi, i0, j0, k0)) * (_vel(v, i0, j0, k0, a, bc_sign) + va)
        east = _vel(v, i1, j1, k1, c, bc_sign)
        west = _vel(v, i0, j0, k0, c, bc_sign)
        # (far upwind, upwind, downwind) of each face; one call site each (compile time)
        if flux_up > 0.0:
            uu, u, d = west, vc, east
        else:
            uu, u, d = _vel(v, i2, j2, k2, c, bc_sign), east, vc
        up = _limited_face_value(uu, u, d)
        if flux_dn > 0.0:
            uu, u, d = _vel(v, im, jm, km, c, bc_sign), west, vc
        else:
            uu, u, d = east, vc, west
        dn = _limited_face_value(uu, u, d)
        total += (flux_up * up - flux_dn * dn) / spacing[a]
    return total


@njit(cache=True, inline="always")
def _grid_advection(v, phi, i, j, k, c, stretch, bc_sign):
    """The moving grid's share of the momentum rate of cell (i,j,k), component c (module
    docstring): s (phi_(k+1/2) (k+1) v_(k+1/2) - phi_(k-1/2) k v_(k-1/2)) / phi - s v, v_f of the
    cell the relative flux -w_f comes from (above when the grid stretches, s > 0)."""
    ph = phi[i, j, k]
    vc = v[i, j, k, c]
    phi_up = 0.5 * (ph + _cell(phi, i, j, k + 1))
    phi_dn = 0.5 * (ph + _cell(phi, i, j, k - 1))
    if stretch > 0.0:
        v_up = _vel(v, i, j, k + 1, c, bc_sign)
        v_dn = vc
    else:
        v_up = vc
        v_dn = _vel(v, i, j, k - 1, c, bc_sign)
    return stretch * ((k + 1) * phi_up * v_up - k * phi_dn * v_dn) / ph - stretch * vc


@njit(cache=True, parallel=True)
def predict(
    v,
    grad_p,
    phi,
    dphi,
    f_i,
    k_drag,
    spacing,
    gravity,
    bc_sign,
    rho,
    mu,
    beta,
    pressure_in_solid,
    dt,
    v_star,
    mobility,
):
    """Predicted velocity v* (step 1 of the module docstring) and the pressure mobility of each
    cell, mobility = phi D (A) or D (B) with D = 1/(1 + dt k_drag/(rho phi)).

    The drag on the fluid is f_i + k_drag (v_new - v): f_i at the old fluid velocity v, k_drag its
    derivative (kernels/fluid/drag.py), so it is implicit in the fluid's own velocity. Solving the
    momentum balance for v_new divides every explicit increment, the pressure's included, by
    1 + dt k_drag/(rho phi): v* = v + D dt [...], and v_new = v* - D dt/rho (1 or 1/phi) grad eps =
    v* - dt/rho (mobility/phi) grad eps, with the same D in the pressure equation's faces."""
    nx, ny, nz = phi.shape
    for ii in prange(nx):
        i = np.int64(ii)  # the prange index is unsigned: i - 1 must not wrap
        for j in range(ny):
            for k in range(nz):
                ph = phi[i, j, k]
                inv = 1.0 / (rho * ph)
                p_factor = 1.0 / rho if pressure_in_solid else inv
                implicit = dt * k_drag[i, j, k] * inv
                for c in range(3):
                    vc = v[i, j, k, c]
                    rate = (
                        mu * inv * _viscous(v, phi, i, j, k, c, spacing, bc_sign)
                        - _advection(v, phi, i, j, k, c, spacing, bc_sign) / ph
                        - beta * p_factor * grad_p[i, j, k, c]
                        + gravity[c]
                        - inv * f_i[i, j, k, c]
                    )
                    explicit = vc + dt * rate - vc * dphi[i, j, k] * dt / ph
                    v_star[i, j, k, c] = (explicit + implicit * vc) / (1.0 + implicit)
                mobility[i, j, k] = (ph if pressure_in_solid else 1.0) / (1.0 + implicit)


@njit(cache=True, inline="always")
def _face_flux(
    v_star, phi, mobility, grad_p, p, i, j, k, a, spacing, bc_sign, p_kind, p_bound, beta, rho, dt
):
    """phi_f v_f through the face between cell (i,j,k) and its +a neighbour (either may be a z
    ghost): the mean of the two predicted velocities, in which the old pressure's share (beta > 0)
    is taken with the compact face gradient instead of the mean of the two central ones (Rhie &
    Chow 1983), so an odd-even pressure mode is seen and removed."""
    nz = phi.shape[2]
    i1, j1, k1 = _shift(i, j, k, a, 1)
    phi_f = 0.5 * (_cell(phi, i, j, k) + _cell(phi, i1, j1, k1))
    flux = 0.5 * phi_f * (_vel(v_star, i, j, k, a, bc_sign) + _vel(v_star, i1, j1, k1, a, bc_sign))
    if beta == 0.0:
        return flux
    if a == 2 and ((k < 0 and p_kind[0] == 0) or (k1 >= nz and p_kind[1] == 0)):
        return flux  # a no-flow wall: zero
    m0 = _cell(mobility, i, j, k)
    m1 = _cell(mobility, i1, j1, k1)
    central = 0.5 * (
        m0 / _cell(phi, i, j, k) * _cell_vec(grad_p, i, j, k, a)
        + m1 / _cell(phi, i1, j1, k1) * _cell_vec(grad_p, i1, j1, k1, a)
    )
    compact = (_pres(p, i1, j1, k1, p_kind, p_bound) - _pres(p, i, j, k, p_kind, p_bound)) / spacing[a]
    return flux + beta * dt / rho * (phi_f * central - 0.5 * (m0 + m1) * compact)


@njit(cache=True, inline="always")
def _cell_vec(f, i, j, k, a):
    """f[i,j,k,a] of a cell vector field, periodic in x and y, the boundary cell's in z ghosts."""
    nz = f.shape[2]
    k = 0 if k < 0 else (nz - 1 if k >= nz else k)
    return f[_wrap(i, f.shape[0]), _wrap(j, f.shape[1]), k, a]


@njit(cache=True, parallel=True)
def pressure_rhs(
    v_star, phi, dphi, mobility, grad_p, p, spacing, bc_sign, p_kind, p_bound, beta, rho, dt, rhs
):
    """rhs = -rho/dt (div(phi_f v*_f) + dphi): the right-hand side b of -div(a grad eps) = b, with
    the face fluxes of `_face_flux` (zero at a no-flow wall); p, grad_p and p_bound of the old
    pressure."""
    nx, ny, nz = phi.shape
    for ii in prange(nx):
        i = np.int64(ii)  # the prange index is unsigned: i - 1 must not wrap
        for j in range(ny):
            for k in range(nz):
                div = 0.0
                for a in range(3):
                    i0, j0, k0 = _shift(i, j, k, a, -1)
                    up = _face_flux(
                        v_star,
                        phi,
                        mobility,
                        grad_p,
                        p,
                        i,
                        j,
                        k,
                        a,
                        spacing,
                        bc_sign,
                        p_kind,
                        p_bound,
                        beta,
                        rho,
                        dt,
                    )
                    dn = _face_flux(
                        v_star,
                        phi,
                        mobility,
                        grad_p,
                        p,
                        i0,
                        j0,
                        k0,
                        a,
                        spacing,
                        bc_sign,
                        p_kind,
                        p_bound,
                        beta,
                        rho,
                        dt,
                    )
                    div += (up - dn) / spacing[a]
                rhs[i, j, k] = -rho / dt * (div + dphi[i, j, k])


@njit(cache=True, parallel=True)
def add_grid_motion(v, phi, k_drag, bc_sign, rho, dt, stretch, v_star):
    """v* += dt D (the moving grid's momentum rate) after `predict` (module docstring; D =
    1/(1 + dt k_drag/(rho phi)) as in `predict`), from the old velocity v."""
    nx, ny, nz = phi.shape
    for ii in prange(nx):
        i = np.int64(ii)
        for j in range(ny):
            for k in range(nz):
                d = 1.0 / (1.0 + dt * k_drag[i, j, k] / (rho * phi[i, j, k]))
                for c in range(3):
                    v_star[i, j, k, c] += dt * d * _grid_advection(v, phi, i, j, k, c, stretch, bc_sign)


@njit(cache=True, parallel=True)
def add_grid_source(phi, dphi, rho, dt, stretch, rhs):
    """rhs -= rho/dt (the moving grid's source) after `pressure_rhs` (module docstring)."""
    nx, ny, nz = phi.shape
    for ii in prange(nx):
        i = np.int64(ii)
        for j in range(ny):
            for k in range(nz):
                rhs[i, j, k] -= rho / dt * _grid_source(phi, dphi, i, j, k, stretch, dt)


@njit(cache=True, inline="always")
def _grid_source(phi, dphi, i, j, k, stretch, dt):
    """phi_old s - s (phi_(k+1/2) (k+1) - phi_(k-1/2) k): the cell's volume change less the
    grid's flux div_z(phi_f w_f), per unit volume and time (module docstring)."""
    ph = phi[i, j, k]
    phi_up = 0.5 * (ph + _cell(phi, i, j, k + 1))
    phi_dn = 0.5 * (ph + _cell(phi, i, j, k - 1))
    return (ph - dt * dphi[i, j, k]) * stretch - stretch * ((k + 1) * phi_up - k * phi_dn)


@njit(cache=True)
def top_outflow(
    v_star,
    phi,
    mobility,
    grad_p,
    p,
    eps,
    az,
    spacing,
    bc_sign,
    p_kind,
    p_bound,
    eps_bound,
    beta,
    rho,
    dt,
    stretch,
):
    """Fluid volume leaving through the open top face per unit time, relative to the face moving
    at w = nz dz s [m^3/s]: the sum over the top faces of dx dy (F - phi_f w), F the corrected
    face flux the pressure equation balances, F = F* - dt/rho a_f 2 (eps_top - eps)/dz (F* of
    `_face_flux`, eps_top = eps_bound[1]). Call after the solve and before `correct` (p, grad_p,
    p_bound still the old pressure's). Serial, in a fixed order."""
    nx, ny, nz = phi.shape
    k = nz - 1
    w = nz * spacing[2] * stretch
    total = 0.0
    for i in range(nx):
        for j in range(ny):
            flux = _face_flux(
                v_star, phi, mobility, grad_p, p, i, j, k, 2, spacing, bc_sign, p_kind, p_bound, beta, rho, dt
            )
            flux -= dt / rho * az[i, j, nz] * 2.0 * (eps_bound[1] - eps[i, j, k]) / spacing[2]
            total += flux - phi[i, j, k] * w
    return total * spacing[0] * spacing[1]


@njit(cache=True, parallel=True)
def correct(
    v_star, eps, phi, mobility, f_i, k_drag, spacing, eps_kind, eps_bound, rho, beta, dt, v, p, f_exchange
):
    """v_new = v* - dt/rho (mobility/phi) grad eps;  p = beta p + eps (step 3); the drag the fluid
    took, f_exchange = f_i + k_drag (v_new - v) [N/m^3], which it receives with the opposite sign."""
    nx, ny, nz = phi.shape
    for ii in prange(nx):
        i = np.int64(ii)  # the prange index is unsigned: i - 1 must not wrap
        for j in range(ny):
            for k in range(nz):
                factor = dt / rho * mobility[i, j, k] / phi[i, j, k]
                for c in range(3):
                    new = v_star[i, j, k, c] - factor * _grad(eps, i, j, k, c, spacing, eps_kind, eps_bound)
                    f_exchange[i, j, k, c] = f_i[i, j, k, c] + k_drag[i, j, k] * (new - v[i, j, k, c])
                    v[i, j, k, c] = new
                p[i, j, k] = beta * p[i, j, k] + eps[i, j, k]


@njit(cache=True)
def first_unstable(v, p, spacing, dt, courant_limit):
    """First cell (flat C index) with a non-finite velocity or pressure (reason 1) or an advective
    Courant number sum |v_a| dt/dx_a above courant_limit (reason 2); -1 if none. Returns (cell,
    reason, value)."""
    nx, ny, nz = p.shape
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                courant = 0.0
                finite = math.isfinite(p[i, j, k])
                for a in range(3):
                    finite = finite and math.isfinite(v[i, j, k, a])
                    courant += abs(v[i, j, k, a]) * dt / spacing[a]
                if not finite:
                    return (i * ny + j) * nz + k, 1, courant
                if courant > courant_limit:
                    return (i * ny + j) * nz + k, 2, courant
    return -1, 0, 0.0


@njit(cache=True)
def max_courant(v, spacing, dt):
    """Largest advective Courant number sum |v_a| dt/dx_a over the cells [-]."""
    nx, ny, nz = v.shape[0], v.shape[1], v.shape[2]
    worst = 0.0
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                courant = 0.0
                for a in range(3):
                    courant += abs(v[i, j, k, a]) * dt / spacing[a]
                worst = max(worst, courant)
    return worst
