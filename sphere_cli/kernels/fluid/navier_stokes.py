"""Porous (volume-averaged) Navier-Stokes on a regular staggered (MAC) grid, by operator
splitting (Langtangen et al. 2002, as in the documentation of the original sphere: Damsgaard et
al. 2015, The Cryosphere 9:2183; the MAC arrangement of Harlow & Welch 1965, Phys. Fluids 8).

Momentum, with porosity phi, fluid density rho, viscosity mu, the body acceleration g (gravity
and any body-force field) and the interaction force f_i the fluid exerts on the particles per
unit volume (the fluid receives -f_i):
  d(phi v)/dt + div(phi v v) = -(phi or 1)/rho grad p + div(phi tau)/rho - f_i/rho + phi g,
  tau = mu (grad v + grad v^T);  pressure factor phi in formulation A (pressure in both phases,
  Zhu et al. 2007 model A), 1 in formulation B (pressure in the fluid only).
Continuity: d phi/dt + div(phi v) = 0.

Grid. Pressure p, porosity phi and its rate dphi live at the cell centres; each velocity
component on the faces normal to it. The face array v_face (nx, ny, nz+1, 3) holds component c
of face (i, j, k) at the centre of cell (i, j, k) shifted by half a cell towards -c: x faces
i = 0 .. nx-1 and y faces j = 0 .. ny-1 (x and y periodic: face n is face 0), z faces
k = 0 .. nz (0 the bottom boundary, nz the top); the x and y components of layer k = nz are not
faces and stay zero. Face porosity phi_f = mean of the two cells either side (the boundary cell
at a z boundary face), edge porosity the mean of the four cells around an edge; the exact lens
porosity of the cells is what the particles give (physics/fluid/porosity.py).

One fluid step of length dt, each face momentum balance divided by its phi_f:
1. predictor  v* = v + dt [-beta (1 or 1/phi_f)/rho grad_f p + div(phi tau)_f/(rho phi_f)
                            - div(phi v v)_f/phi_f + g - f_f/(rho phi_f)] - v dphi_f dt/phi_f,
   the drag's change over the step, k_f (v_new - v), implicit: every explicit increment and the
   pressure correction are divided by 1 + dt k_f/(rho phi_f) (factor D_f); f_f, k_f and dphi_f
   are the means of the two cells' f_i, k_drag and dphi (see `predict`);
2. pressure equation for eps = p_new - beta p from continuity of every cell,
     dphi + div(phi_f v_f) = 0,  phi_f v_f = phi_f v*_f - dt/rho a_f grad_f eps,
     a_f = phi_f D_f (A) or D_f (B):   -div(a_f grad eps) = -rho/dt (div(phi_f v*_f) + dphi),
   the 7-point system of kernels/fluid/poisson.py with these face coefficients, so that after
   the correction the discrete divergence of every cell is the solver's residual;
3. correction v_f = v*_f - dt/rho (a_f/phi_f) grad_f eps, p = beta p + eps.
grad_f is the compact difference across the face, so no odd-even pressure mode exists and no
interpolation of the momentum to the faces (Rhie & Chow) is needed.

Space: viscous stress compact: the normal stress 2 phi mu d_c v_c at the cell centres either
side of a c face, the shear stress phi mu (d_a v_c + d_c v_a) at the edges. Advection
div(phi v v_c) in flux form over the face's control volume: through each of its sides the flux
phi u (phi at the cell centre or edge there, u the mean of the two faces of that component
nearest) carries the value of v_c reconstructed from the upwind face U with a limited slope
(MUSCL, van Leer 1979, J. Comput. Phys. 32, 101; van Leer's limiter psi(r) = (r + |r|)/(1 + r),
Sweby 1984, SIAM J. Numer. Anal. 21, 995):
  v_s = v_U + 0.5 L(v_U - v_UU, v_D - v_U),  L(a, b) = 2ab/(a + b) if ab > 0, else 0;
with forward Euler this is TVD for sum |u_i| dt/dx_i <= 1/2 (Harten 1983, J. Comput. Phys. 49).

z boundaries. A no-flow face holds v_z = 0, a prescribed-velocity face v_z = U/phi_f (U the
superficial velocity; both Neumann faces of the pressure equation, their flux in its right-hand
side); a prescribed-pressure face (bottom k = 0 or top
k = nz) has its own momentum balance, with the pressure ghost 2 p_b - p of the cell inside (so
grad_f p = 2 (p_inside - p_b)/dz there, the Dirichlet face of the pressure equation) and the
normal velocity mirrored about the face (zero gradient). The tangential components see ghost
cells k = -1 - m and nz + m equal to sign * the component of cell m from that boundary: bc_sign
(2,3) (row 0 bottom, row 1 top) is -1 for the normal component at a no-flow face and the
tangential ones at a no-slip face, +1 otherwise. Porosity ghost = boundary cell.

Moving grid (`[fluid.grid] follow_top_wall`): the grid's top is the top wall at height H(t)
above the bottom, and its nz layers stretch uniformly, so a plane at z-index zeta (in cells)
moves with w = zeta dz H'/H and every control volume changes at the same rate s = (H_new -
H_old)/(H_new dt) [1/s]: the geometric conservation law (Thomas & Lombard 1979, AIAA J. 17)
holds on every step. Fields belong to the moving cells (arbitrary Lagrangian-Eulerian form,
Hirt et al. 1974, J. Comput. Phys. 14): over a volume moving with the grid
  (1/V) d(phi V)/dt + div(phi (v - w)) = 0,  (1/V) d(phi V v)/dt + div(phi v (v - w)) = (forces),
so that (`add_grid_source`, `add_grid_motion`):
  pressure source   dphi + phi_old s - s (phi_(k+1) (k+1) - phi_k k),  phi_old = phi - dt dphi,
                    phi_k the porosity of z face k;
  momentum rate     + s (zeta_up phi_up v_up - zeta_dn phi_dn v_dn)/phi_f - s v of a face whose
                    control volume spans zeta_dn .. zeta_up (k .. k+1 for x and y faces, k-1/2 ..
                    k+1/2 for z faces), v_up, v_dn upwind of the flux relative to the grid.
A uniform phi and v stay so; summed over a column, the pore volume changes by exactly the
relative flux through the top face, which must be open (prescribed pressure). With particles,
dphi is not the rate of two measures of the moving cells (those do not cancel the porosity the
moving faces carry where cells slide past grains at rest): the module measures the rate at
points fixed in space, `moving_cell_rate` gives the dphi that makes the pressure source that
rate, and kernels/fluid/porosity.py `rate_in_grains_frame` takes each cell's between that and
the cells' own by the grains' motion.

Arguments: v_face, v_star, mobility, acceleration (nx,ny,nz+1,3) [m/s, m/s, -, m/s^2] on the
faces; edges (nx,ny,nz+1,3) [-] the edge porosities of `edge_porosity`; normal (nx,ny,nz+2,3)
[m/s] and shear (nx,ny,nz+1,3) [1/s] the viscous stresses of `viscous_stresses` (phi times the
velocity difference across a cell, and phi times the shear rate at an edge); flux
(nx,ny,nz+2,3,3) [m^2/s^2] the advective fluxes of `advective_fluxes`; v, f_i, f_exchange, grad_p (nx,ny,nz,3)
[m/s, N/m^3, N/m^3, Pa/m] at the cell centres (v from the fluxes of the cell's faces,
`cell_velocity`); p, eps, phi, dphi, k_drag, rhs (nx,ny,nz) [Pa, Pa, -, 1/s, kg/(m^3 s),
Pa/m^2]; spacing (3,) [m]; bc_sign (2,3) float64; p_kind (2,) int64, 1 = prescribed pressure,
0 = no flow, 2 = prescribed velocity; p_bound (2,) [Pa] boundary pressure (bottom, top); inflow
(2,) [m/s] superficial velocity along +z of a prescribed-velocity face; rho [kg/m^3]; mu [Pa s];
beta [-]; pressure_in_solid 1 for formulation A, 0 for B; dt [s] the fluid step; stretch [1/s]
the moving grid's s; lo, hi: the x planes lo .. hi - 1 that advective_fluxes, viscous_stresses
and predict compute (lo may be -1 and hi nx + 1: x is periodic), one MPI rank's slab and, for
the first two, the planes beside it that predict reads (0, nx on one rank).
"""

import math

import numpy as np
from numba import njit, prange


# Not inline="always" (nor _shift, _far, _limited_face_value): Numba's IR inlining of these
# scalar helpers at some hundred call sites was much of the module's compile time, and LLVM
# inlines them still, the run time unchanged. The helpers that take arrays stay inlined by Numba:
# without that the fluid step ran twice as long (docs/performance.md).
@njit(cache=True)
def _wrap(i, n):
    if i < 0:
        return i + n
    if i >= n:
        return i - n
    return i


@njit(cache=True)
def _shift(i, j, k, a, s):
    """The index s (= +1 or -1) steps from (i,j,k) along axis a (not wrapped)."""
    if a == 0:
        return i + s, j, k
    if a == 1:
        return i, j + s, k
    return i, j, k + s


@njit(cache=True)
def _far(i, j, k, a, s, nx, ny):
    """The index two steps s (= +1 or -1) from (i,j,k) along axis a, wrapped in x and y so that
    the single wrap of the readers suffices even on a grid one cell wide."""
    if a == 0:
        return _wrap(_wrap(i + 2 * s, nx), nx), j, k
    if a == 1:
        return i, _wrap(_wrap(j + 2 * s, ny), ny), k
    return i, j, k + 2 * s


@njit(cache=True, inline="always")
def _face(u, i, j, k, c, bc_sign):
    """Component c of face (i,j,k) (module docstring), periodic in x and y (at most one period
    outside), the z ghosts mirrored: a z face -m or nz + m is sign * the face m inside from that
    boundary; an x or y face in ghost cell -1 - m or nz + m is sign * the one of cell m."""
    nz = u.shape[2] - 1
    i = _wrap(i, u.shape[0])
    j = _wrap(j, u.shape[1])
    if c == 2:
        if k < 0:
            return bc_sign[0, 2] * u[i, j, min(-k, nz), 2]
        if k > nz:
            return bc_sign[1, 2] * u[i, j, max(2 * nz - k, 0), 2]
        return u[i, j, k, 2]
    if k < 0:
        return bc_sign[0, c] * u[i, j, min(-1 - k, nz - 1), c]
    if k >= nz:
        return bc_sign[1, c] * u[i, j, max(2 * nz - 1 - k, 0), c]
    return u[i, j, k, c]


@njit(cache=True, inline="always")
def _cell(f, i, j, k):
    """f[i,j,k] of a cell field, periodic in x and y, the boundary cell's value in z ghosts."""
    nz = f.shape[2]
    k = 0 if k < 0 else (nz - 1 if k >= nz else k)
    return f[_wrap(i, f.shape[0]), _wrap(j, f.shape[1]), k]


@njit(cache=True, inline="always")
def _cell_vec(f, i, j, k, a):
    """f[i,j,k,a] of a cell vector field, periodic in x and y, the boundary cell's in z ghosts."""
    nz = f.shape[2]
    k = 0 if k < 0 else (nz - 1 if k >= nz else k)
    return f[_wrap(i, f.shape[0]), _wrap(j, f.shape[1]), k, a]


@njit(cache=True, inline="always")
def _pres(p, i, j, k, p_kind, p_bound):
    """p[i,j,k] with the z ghost cells of a pressure: 2 p_b - p of the boundary cell at a
    prescribed-pressure face, linear extrapolation at a no-flow or prescribed-velocity face
    (which the momentum balances never read: their velocity is given)."""
    nz = p.shape[2]
    i = _wrap(i, p.shape[0])
    j = _wrap(j, p.shape[1])
    if k < 0:
        if p_kind[0] == 1:
            return 2.0 * p_bound[0] - p[i, j, 0]
        return 2.0 * p[i, j, 0] - p[i, j, 1] if nz > 1 else p[i, j, 0]
    if k >= nz:
        if p_kind[1] == 1:
            return 2.0 * p_bound[1] - p[i, j, nz - 1]
        return 2.0 * p[i, j, nz - 1] - p[i, j, nz - 2] if nz > 1 else p[i, j, 0]
    return p[i, j, k]


@njit(cache=True, inline="always")
def _phi_face(phi, i, j, k, c):
    """Porosity of face (i,j,k) of component c: the mean of the cells either side."""
    i0, j0, k0 = _shift(i, j, k, c, -1)
    return 0.5 * (_cell(phi, i, j, k) + _cell(phi, i0, j0, k0))


@njit(cache=True, parallel=True)
def edge_porosity(phi, edges):
    """edges[i,j,k,m]: the porosity of the edge along axis m at the corner of cell (i,j,k) half a
    cell towards -1 along both other axes, the mean of the four cells around it (z ghosts: the
    boundary cell); layer k = nz is the top's (edges along x and y) [-]. Once per fluid step, so
    that the momentum stencils read each edge once."""
    nx, ny, nz = phi.shape
    for ii in prange(nx):
        i = np.int64(ii)
        for j in range(ny):
            edge_porosity_column(phi, edges, i, j)


@njit(cache=True, inline="always")
def edge_porosity_column(phi, edges, i, j):
    nz = phi.shape[2]
    for k in range(nz + 1):
        for m in range(3):
            c = 1 if m == 0 else 0
            a = 1 if m == 2 else 2
            ic, jc, kc = _shift(i, j, k, c, -1)
            ia, ja, ka = _shift(i, j, k, a, -1)
            ib, jb, kb = _shift(ic, jc, kc, a, -1)
            edges[i, j, k, m] = 0.25 * (
                _cell(phi, i, j, k) + _cell(phi, ic, jc, kc) + _cell(phi, ia, ja, ka) + _cell(phi, ib, jb, kb)
            )


@njit(cache=True, inline="always")
def _edge(edges, i, j, k, c, a):
    """Porosity of the edge half a cell along +a from face (i,j,k) of component c (a != c), from
    `edge_porosity`: the edge along the third axis at index (i,j,k) + a."""
    i1, j1, k1 = _shift(i, j, k, a, 1)
    return edges[_wrap(i1, edges.shape[0]), _wrap(j1, edges.shape[1]), k1, 3 - c - a]


@njit(cache=True, inline="always")
def _is_face(k, c, nz, p_kind):
    """Whether (i,j,k) of component c is a face with a momentum balance: not the unused layer
    k = nz of x and y, not a no-flow or prescribed-velocity z boundary."""
    if c < 2:
        return k < nz
    if k == 0:
        return p_kind[0] == 1
    if k == nz:
        return p_kind[1] == 1
    return True


@njit(cache=True, parallel=True)
def pressure_gradient(p, spacing, p_kind, p_bound, grad_p):
    """grad_p of every cell, what the particles feel: central differences with the pressure
    ghosts [Pa/m], the mean of the compact gradients of its two faces of each component (at a no-flow
    or prescribed-velocity z boundary the ghost extrapolates: the gradient of the face inside)."""
    nx, ny, nz = p.shape
    for ii in prange(nx):
        i = np.int64(ii)  # the prange index is unsigned: i - 1 must not wrap
        for j in range(ny):
            pressure_gradient_column(p, spacing, p_kind, p_bound, grad_p, i, j)


@njit(cache=True, inline="always")
def pressure_gradient_column(p, spacing, p_kind, p_bound, grad_p, i, j):
    nz = p.shape[2]
    for k in range(nz):
        for a in range(3):
            i1, j1, k1 = _shift(i, j, k, a, 1)
            i0, j0, k0 = _shift(i, j, k, a, -1)
            grad_p[i, j, k, a] = (
                _pres(p, i1, j1, k1, p_kind, p_bound) - _pres(p, i0, j0, k0, p_kind, p_bound)
            ) / (2.0 * spacing[a])


@njit(cache=True, parallel=True, error_model="numpy")
def viscous_stresses(v_face, phi, edges, spacing, bc_sign, normal, shear, lo, hi):
    """The viscous stresses / viscosity where the momentum balances of the faces need them, each
    computed once: normal[i,j,k+1,c] = phi (d_c v_c) at the centre of cell (i,j,k) (k = -1 .. nz,
    the z ghosts included), between its faces of component c; shear[i,j,k,m] = phi_edge (d_a v_c
    + d_c v_a) at the edge of `edge_porosity` along m, c and a the other two axes."""
    nx, ny, nz = phi.shape
    for t in prange(hi - lo):
        i = np.int64(_wrap(lo + np.int64(t), nx))  # the prange index is unsigned: i - 1 must not wrap
        for j in range(ny):
            viscous_stresses_column(v_face, phi, edges, spacing, bc_sign, normal, shear, i, j)


@njit(cache=True, inline="always")
def viscous_stresses_column(v_face, phi, edges, spacing, bc_sign, normal, shear, i, j):
    nz = phi.shape[2]
    for k in range(-1, nz + 1):
        for c in range(3):
            i1, j1, k1 = _shift(i, j, k, c, 1)
            normal[i, j, k + 1, c] = _cell(phi, i, j, k) * (
                _face(v_face, i1, j1, k1, c, bc_sign) - _face(v_face, i, j, k, c, bc_sign)
            )
        if k < 0:
            continue
        for m in range(3):
            c = 1 if m == 0 else 0
            a = 1 if m == 2 else 2
            ia, ja, ka = _shift(i, j, k, a, -1)
            ic, jc, kc = _shift(i, j, k, c, -1)
            uc = _face(v_face, i, j, k, c, bc_sign)
            ua = _face(v_face, i, j, k, a, bc_sign)
            shear[i, j, k, m] = edges[i, j, k, m] * (
                (uc - _face(v_face, ia, ja, ka, c, bc_sign)) / spacing[a]
                + (ua - _face(v_face, ic, jc, kc, a, bc_sign)) / spacing[c]
            )


@njit(cache=True, inline="always")
def _viscous(normal, shear, i, j, k, c, spacing):
    """div(phi (grad v + grad v^T))_c / viscosity at face (i,j,k) of component c, from the
    stresses of `viscous_stresses`: the normal stress at the cell centres either side, the shear
    stresses at the four edges around."""
    nx, ny = shear.shape[0], shear.shape[1]
    total = 0.0
    for a in range(3):
        if a == c:
            i0, j0, k0 = _shift(i, j, k, c, -1)
            up = normal[i, j, k + 1, c]
            dn = normal[_wrap(i0, nx), _wrap(j0, ny), k0 + 1, c]
            total += 2.0 * (up - dn) / (spacing[a] * spacing[a])
        else:
            i1, j1, k1 = _shift(i, j, k, a, 1)
            m = 3 - c - a
            up = shear[_wrap(i1, nx), _wrap(j1, ny), k1, m]
            dn = shear[i, j, k, m]
            total += (up - dn) / spacing[a]
    return total


@njit(cache=True)
def _limited_face_value(upwind_upwind, upwind, downwind):
    """v_U + 0.5 L(v_U - v_UU, v_D - v_U) with van Leer's limited slope L(a, b) = 2ab/(a + b),
    0 unless a and b have the same sign."""
    back = upwind - upwind_upwind
    ahead = downwind - upwind
    product = back * ahead
    if product > 0.0:
        return upwind + product / (back + ahead)
    return upwind


@njit(cache=True, parallel=True, error_model="numpy")
def advective_fluxes(v_face, phi, edges, bc_sign, flux, lo, hi):
    """flux[i,j,k,c,a] = phi u v_c through the side of the control volume of face (i,j,k) of
    component c half a cell towards -a (module docstring): the transport phi u there (phi of the
    cell centre for a = c, of the edge otherwise; u the mean of the two faces of component a
    nearest) times v_c reconstructed from the upwind face with van Leer's limited slope. Each
    side is the -a side of one face and the +a side of the one before it: computed once here, so
    that `predict` takes the divergence. Layers k = 0 .. nz + 1 (the +z side of the top faces)."""
    nx, ny, nz = phi.shape
    for t in prange(hi - lo):
        i = np.int64(_wrap(lo + np.int64(t), nx))  # the prange index is unsigned: i - 1 must not wrap
        for j in range(ny):
            advective_fluxes_column(v_face, phi, edges, bc_sign, flux, i, j)


@njit(cache=True, inline="always")
def advective_fluxes_column(v_face, phi, edges, bc_sign, flux, i, j):
    nx, ny, nz = phi.shape
    for k in range(nz + 2):
        for c in range(3):
            uc = _face(v_face, i, j, k, c, bc_sign)
            for a in range(3):
                if k > nz and (a != 2 or c != 2):  # beyond the +z side of the top z faces
                    flux[i, j, k, c, a] = 0.0
                    continue
                i0, j0, k0 = _shift(i, j, k, a, -1)
                west = _face(v_face, i0, j0, k0, c, bc_sign)
                if a == c:
                    transport = _cell(phi, i0, j0, k0) * 0.5 * (west + uc)
                else:
                    ic, jc, kc = _shift(i, j, k, c, -1)
                    transport = (
                        edges[i, j, k, 3 - c - a]
                        * 0.5
                        * (_face(v_face, i, j, k, a, bc_sign) + _face(v_face, ic, jc, kc, a, bc_sign))
                    )
                # (far upwind, upwind, downwind) of the side; one call site each (compile time)
                if a == 2 and c != 2 and (k == 0 or k == nz):
                    # a side on a z boundary carries the boundary's own value, the mean
                    # of the faces either side (0 at a no-slip face, through which a
                    # prescribed or open flow brings no tangential velocity)
                    flux[i, j, k, c, a] = transport * 0.5 * (west + uc)
                    continue
                if transport > 0.0:
                    im, jm, km = _far(i, j, k, a, -1, nx, ny)
                    value = _limited_face_value(_face(v_face, im, jm, km, c, bc_sign), west, uc)
                else:
                    i1, j1, k1 = _shift(i, j, k, a, 1)
                    value = _limited_face_value(_face(v_face, i1, j1, k1, c, bc_sign), uc, west)
                flux[i, j, k, c, a] = transport * value


@njit(cache=True, inline="always")
def _advection(flux, i, j, k, c, spacing):
    """div(phi v v_c) over the control volume of face (i,j,k) of component c from the side
    fluxes of `advective_fluxes`."""
    nx, ny = flux.shape[0], flux.shape[1]
    i1 = i + 1 if i + 1 < nx else 0
    j1 = j + 1 if j + 1 < ny else 0
    total = (flux[i1, j, k, c, 0] - flux[i, j, k, c, 0]) / spacing[0]
    total += (flux[i, j1, k, c, 1] - flux[i, j, k, c, 1]) / spacing[1]
    total += (flux[i, j, k + 1, c, 2] - flux[i, j, k, c, 2]) / spacing[2]
    return total


# error_model="numpy": a division by zero gives inf or nan (caught by the fluid's checks) instead
# of a Python exception, which spares a test on every division of the stencils
@njit(cache=True, parallel=True, error_model="numpy")
def predict(
    v_face,
    p,
    phi,
    normal,
    shear,
    flux,
    dphi,
    f_i,
    k_drag,
    acceleration,
    spacing,
    bc_sign,
    p_kind,
    p_bound,
    rho,
    mu,
    beta,
    pressure_in_solid,
    dt,
    inflow,
    v_star,
    mobility,
    lo,
    hi,
):
    """Predicted face velocities v* (step 1 of the module docstring) and the pressure
    equation's face coefficients, mobility = phi_f D_f (A) or D_f (B), D_f = 1/(1 + dt k_f/(rho
    phi_f)). A face without a momentum balance (module docstring) gets mobility 0 and keeps its
    prescribed velocity: inflow[row] / phi_f at a z boundary (row 0 bottom, 1 top; the
    superficial velocity of a prescribed-velocity face, 0 at a no-flow face), 0 elsewhere.

    The drag on the fluid of a face is f_f + k_f (v_new - v): f_f at the old velocity, k_f its
    derivative, so it is implicit in the fluid's own velocity. Solving the face's momentum
    balance for v_new divides every explicit increment, the pressure's included, by 1 + dt k_f/
    (rho phi_f): v* = v + D_f dt [...], v_new = v* - dt/rho (mobility/phi_f) grad eps."""
    nx, ny = phi.shape[0], phi.shape[1]
    # one loop over the columns: a loop over j in one over the planes around the inlined column
    # took 4.7 ms against 2.4 ms at 32^3 (one thread)
    for t in prange((hi - lo) * ny):
        i = np.int64(_wrap(lo + np.int64(t // ny), nx))  # the prange index is unsigned: i - 1 must not wrap
        j = np.int64(t % ny)
        predict_column(
            v_face, p, phi, normal, shear, flux, dphi, f_i, k_drag, acceleration, spacing, bc_sign, p_kind,
            p_bound, rho, mu, beta, pressure_in_solid, dt, inflow, v_star, mobility, i, j,
        )  # fmt: skip


@njit(cache=True, inline="always")
def predict_column(
    v_face, p, phi, normal, shear, flux, dphi, f_i, k_drag, acceleration, spacing, bc_sign, p_kind, p_bound,
    rho, mu, beta, pressure_in_solid, dt, inflow, v_star, mobility, i, j,
):  # fmt: skip
    nz = phi.shape[2]
    for k in range(nz + 1):
        for c in range(3):
            if not _is_face(k, c, nz, p_kind):
                prescribed = 0.0
                if c == 2:
                    prescribed = inflow[0 if k == 0 else 1] / _phi_face(phi, i, j, k, 2)
                v_star[i, j, k, c] = prescribed
                mobility[i, j, k, c] = 0.0
                continue
            i0, j0, k0 = _shift(i, j, k, c, -1)
            ph = _phi_face(phi, i, j, k, c)
            rate_phi = 0.5 * (_cell(dphi, i, j, k) + _cell(dphi, i0, j0, k0))
            force = 0.5 * (_cell_vec(f_i, i, j, k, c) + _cell_vec(f_i, i0, j0, k0, c))
            coefficient = 0.5 * (_cell(k_drag, i, j, k) + _cell(k_drag, i0, j0, k0))
            grad = (_pres(p, i, j, k, p_kind, p_bound) - _pres(p, i0, j0, k0, p_kind, p_bound)) / spacing[c]
            inv = 1.0 / (rho * ph)
            p_factor = 1.0 / rho if pressure_in_solid else inv
            implicit = dt * coefficient * inv
            uc = v_face[i, j, k, c]
            rate = (
                mu * inv * _viscous(normal, shear, i, j, k, c, spacing)
                - _advection(flux, i, j, k, c, spacing) / ph
                - beta * p_factor * grad
                + acceleration[i, j, k, c]
                - inv * force
            )
            explicit = uc + dt * rate - uc * rate_phi * dt / ph
            v_star[i, j, k, c] = (explicit + implicit * uc) / (1.0 + implicit)
            mobility[i, j, k, c] = (ph if pressure_in_solid else 1.0) / (1.0 + implicit)


@njit(cache=True, parallel=True)
def face_coefficients(mobility, ax, ay, az):
    """Copy the face mobilities into the pressure solver's face arrays (kernels/fluid/poisson.py:
    ax (nx+1,ny,nz), ay (nx,ny+1,nz), az (nx,ny,nz+1); the periodic faces nx and ny repeat 0)."""
    nx, ny = ax.shape[0] - 1, ay.shape[1] - 1
    for ii in prange(nx + 1):
        i = np.int64(ii)
        for j in range(ny + 1):
            face_coefficients_column(mobility, ax, ay, az, i, j)


@njit(cache=True, inline="always")
def face_coefficients_column(mobility, ax, ay, az, i, j):
    """face_coefficients of column (i, j) of the (nx + 1) x (ny + 1) columns of faces."""
    nx, ny, nz = ax.shape[0] - 1, ay.shape[1] - 1, ax.shape[2]
    for k in range(nz + 1):
        if j < ny and k < nz:
            ax[i, j, k] = mobility[i % nx, j, k, 0]
        if i < nx and k < nz:
            ay[i, j, k] = mobility[i, j % ny, k, 1]
        if i < nx and j < ny:
            az[i, j, k] = mobility[i, j, k, 2]


@njit(cache=True, inline="always")
def _divergence(v_face, phi, i, j, k, spacing):
    """div(phi_f v_f) of cell (i,j,k): the net flux out through its six faces per volume."""
    nx, ny = phi.shape[0], phi.shape[1]
    i1 = i + 1 if i + 1 < nx else 0
    j1 = j + 1 if j + 1 < ny else 0
    div = (
        _phi_face(phi, i1, j, k, 0) * v_face[i1, j, k, 0] - _phi_face(phi, i, j, k, 0) * v_face[i, j, k, 0]
    ) / spacing[0]
    div += (
        _phi_face(phi, i, j1, k, 1) * v_face[i, j1, k, 1] - _phi_face(phi, i, j, k, 1) * v_face[i, j, k, 1]
    ) / spacing[1]
    div += (
        _phi_face(phi, i, j, k + 1, 2) * v_face[i, j, k + 1, 2]
        - _phi_face(phi, i, j, k, 2) * v_face[i, j, k, 2]
    ) / spacing[2]
    return div


@njit(cache=True, parallel=True)
def pressure_rhs(v_star, phi, dphi, spacing, rho, dt, rhs):
    """rhs = -rho/dt (div(phi_f v*_f) + dphi): the right-hand side b of -div(a grad eps) = b."""
    nx, ny, nz = phi.shape
    for ii in prange(nx):
        i = np.int64(ii)  # the prange index is unsigned: i + 1 must stay an integer
        for j in range(ny):
            pressure_rhs_column(v_star, phi, dphi, spacing, rho, dt, rhs, i, j)


@njit(cache=True, inline="always")
def pressure_rhs_column(v_star, phi, dphi, spacing, rho, dt, rhs, i, j):
    nz = phi.shape[2]
    for k in range(nz):
        rhs[i, j, k] = -rho / dt * (_divergence(v_star, phi, i, j, k, spacing) + dphi[i, j, k])


@njit(cache=True, parallel=True)
def continuity_error(v_face, phi, dphi, spacing, out):
    """out = dphi + div(phi_f v_f) of every cell [1/s]: zero for a fluid that conserves volume."""
    nx, ny, nz = phi.shape
    for ii in prange(nx):
        i = np.int64(ii)  # the prange index is unsigned: i + 1 must stay an integer
        for j in range(ny):
            for k in range(nz):
                out[i, j, k] = _divergence(v_face, phi, i, j, k, spacing) + dphi[i, j, k]


@njit(cache=True, parallel=True)
def correct(v_star, eps, phi, mobility, spacing, p_kind, eps_bound, rho, beta, dt, v_face, p):
    """v_f = v*_f - dt/rho (mobility/phi_f) grad_f eps (v*_f, the prescribed value, on a face
    without a momentum balance); p = beta p + eps."""
    nx, ny, nz = phi.shape
    for ii in prange(nx):
        i = np.int64(ii)  # the prange index is unsigned: i - 1 must not wrap
        for j in range(ny):
            correct_column(
                v_star, eps, phi, mobility, spacing, p_kind, eps_bound, rho, beta, dt, v_face, p, i, j
            )


@njit(cache=True, inline="always")
def correct_column(v_star, eps, phi, mobility, spacing, p_kind, eps_bound, rho, beta, dt, v_face, p, i, j):
    nz = phi.shape[2]
    for k in range(nz + 1):
        for c in range(3):
            if not _is_face(k, c, nz, p_kind):
                v_face[i, j, k, c] = v_star[i, j, k, c]
                continue
            i0, j0, k0 = _shift(i, j, k, c, -1)
            ph = _phi_face(phi, i, j, k, c)
            grad = (
                _pres(eps, i, j, k, p_kind, eps_bound) - _pres(eps, i0, j0, k0, p_kind, eps_bound)
            ) / spacing[c]
            v_face[i, j, k, c] = v_star[i, j, k, c] - dt / rho * mobility[i, j, k, c] / ph * grad
        if k < nz:
            p[i, j, k] = beta * p[i, j, k] + eps[i, j, k]


@njit(cache=True, parallel=True)
def cell_velocity(v_face, v_old, phi, f_i, k_drag, p_kind, v, f_exchange):
    """The cell-centred interstitial velocity v = mean of the fluxes phi_f v_f through the cell's
    two faces of each component / phi: the flux a cell carries, which is what its particles feel
    (a plain mean of the face velocities would understate it beside a porosity jump); and what
    the faces took of the cell's drag in the step from v_old to v_face, f_exchange = f_i +
    k_drag (mean over the two faces of v_new - v_old) [N/m^3]: each face with a momentum balance
    takes the mean of its two cells' f_i + k_drag (v_new - v_old), so these sum to what the fluid
    received, with the opposite sign. A z boundary face without one (no flow, prescribed
    velocity) passes its half of the boundary cell's f_i to the boundary, and no implicit part."""
    nx, ny = v.shape[0], v.shape[1]
    for ii in prange(nx):
        i = np.int64(ii)  # the prange index is unsigned: i + 1 must stay an integer
        for j in range(ny):
            cell_velocity_column(v_face, v_old, phi, f_i, k_drag, p_kind, v, f_exchange, i, j)


@njit(cache=True, inline="always")
def cell_velocity_column(v_face, v_old, phi, f_i, k_drag, p_kind, v, f_exchange, i, j):
    nx, ny, nz = v.shape[0], v.shape[1], v.shape[2]
    i1 = i + 1 if i + 1 < nx else 0
    j1 = j + 1 if j + 1 < ny else 0
    for k in range(nz):
        half = 0.5 / phi[i, j, k]
        kd = 0.5 * k_drag[i, j, k]
        for c in range(3):
            i2, j2, k2 = (i1, j, k) if c == 0 else ((i, j1, k) if c == 1 else (i, j, k + 1))
            v[i, j, k, c] = half * (
                _phi_face(phi, i, j, k, c) * v_face[i, j, k, c]
                + _phi_face(phi, i2, j2, k2, c) * v_face[i2, j2, k2, c]
            )
            change = 0.0
            if _is_face(k, c, nz, p_kind):
                change += v_face[i, j, k, c] - v_old[i, j, k, c]
            if _is_face(k2, c, nz, p_kind):
                change += v_face[i2, j2, k2, c] - v_old[i2, j2, k2, c]
            f_exchange[i, j, k, c] = f_i[i, j, k, c] + kd * change


@njit(cache=True, inline="always")
def _grid_advection(u, phi, edges, i, j, k, c, stretch, bc_sign):
    """The moving grid's share of the momentum rate of face (i,j,k), component c (module
    docstring), v_up and v_dn from the side the flux relative to the grid comes from (above when
    the grid stretches, s > 0)."""
    uc = _face(u, i, j, k, c, bc_sign)
    ph = _phi_face(phi, i, j, k, c)
    if c == 2:
        zeta_up, zeta_dn = k + 0.5, k - 0.5
        phi_up = _cell(phi, i, j, k)
        phi_dn = _cell(phi, i, j, k - 1)
    else:
        zeta_up, zeta_dn = k + 1.0, 1.0 * k
        phi_up = _edge(edges, i, j, k, c, 2)
        phi_dn = _edge(edges, i, j, k - 1, c, 2)
    if stretch > 0.0:
        v_up = _face(u, i, j, k + 1, c, bc_sign)
        v_dn = uc
    else:
        v_up = uc
        v_dn = _face(u, i, j, k - 1, c, bc_sign)
    return stretch * (zeta_up * phi_up * v_up - zeta_dn * phi_dn * v_dn) / ph - stretch * uc


@njit(cache=True, parallel=True)
def add_grid_motion(v_face, phi, edges, k_drag, bc_sign, p_kind, rho, dt, stretch, v_star):
    """v* += dt D_f (the moving grid's momentum rate) after `predict` (module docstring), from
    the old face velocities."""
    nx, ny, nz = phi.shape
    for ii in prange(nx):
        i = np.int64(ii)
        for j in range(ny):
            add_grid_motion_column(
                v_face, phi, edges, k_drag, bc_sign, p_kind, rho, dt, stretch, v_star, i, j
            )


@njit(cache=True, inline="always")
def add_grid_motion_column(v_face, phi, edges, k_drag, bc_sign, p_kind, rho, dt, stretch, v_star, i, j):
    nz = phi.shape[2]
    for k in range(nz + 1):
        for c in range(3):
            if not _is_face(k, c, nz, p_kind):
                continue
            i0, j0, k0 = _shift(i, j, k, c, -1)
            ph = _phi_face(phi, i, j, k, c)
            coefficient = 0.5 * (_cell(k_drag, i, j, k) + _cell(k_drag, i0, j0, k0))
            d = 1.0 / (1.0 + dt * coefficient / (rho * ph))
            v_star[i, j, k, c] += dt * d * _grid_advection(v_face, phi, edges, i, j, k, c, stretch, bc_sign)


@njit(cache=True, parallel=True)
def add_grid_source(phi, dphi, rho, dt, stretch, rhs):
    """rhs -= rho/dt (the moving grid's source) after `pressure_rhs` (module docstring)."""
    nx, ny, nz = phi.shape
    for ii in prange(nx):
        i = np.int64(ii)  # the prange index is unsigned: i + 1 must stay an integer
        for j in range(ny):
            add_grid_source_column(phi, dphi, rho, dt, stretch, rhs, i, j)


@njit(cache=True, inline="always")
def add_grid_source_column(phi, dphi, rho, dt, stretch, rhs, i, j):
    nz = phi.shape[2]
    for k in range(nz):
        ph = phi[i, j, k]
        source = (ph - dt * dphi[i, j, k]) * stretch - stretch * (
            (k + 1) * _phi_face(phi, i, j, k + 1, 2) - k * _phi_face(phi, i, j, k, 2)
        )
        rhs[i, j, k] -= rho / dt * source


@njit(cache=True, parallel=True)
def moving_cell_rate(phi, rate, dt, stretch):
    """rate (nx,ny,nz) [1/s], given the porosity rate at points fixed in space, becomes in place
    the rate of the moving cells that makes the source of `add_grid_source` that rate:
      dphi + (phi - dt dphi) s - s (phi_(k+1) (k+1) - phi_k k) = rate_fixed,
    so that grains at rest give no source whatever the lens estimate of the moving cells."""
    nx, ny, nz = phi.shape
    for ii in prange(nx):
        i = np.int64(ii)
        for j in range(ny):
            for k in range(nz):
                faces = (k + 1) * _phi_face(phi, i, j, k + 1, 2) - k * _phi_face(phi, i, j, k, 2)
                rate[i, j, k] = (rate[i, j, k] - stretch * (phi[i, j, k] - faces)) / (1.0 - dt * stretch)


@njit(cache=True)
def top_outflow(v_face, phi, spacing, stretch):
    """Fluid volume leaving through the open top face per unit time, relative to the face moving
    at w = nz dz s [m^3/s]: the sum over the top faces of dx dy phi_f (v_f - w). Serial, in a
    fixed order."""
    nx, ny, nz = phi.shape
    w = nz * spacing[2] * stretch
    total = 0.0
    for i in range(nx):
        for j in range(ny):
            total += phi[i, j, nz - 1] * (v_face[i, j, nz, 2] - w)
    return total * spacing[0] * spacing[1]


@njit(cache=True, inline="always")
def _cell_courant(v_face, i, j, k, spacing, dt):
    """sum over the axes of the larger |v| of the cell's two faces, times dt/dx_a."""
    nx, ny = v_face.shape[0], v_face.shape[1]
    i1 = i + 1 if i + 1 < nx else 0
    j1 = j + 1 if j + 1 < ny else 0
    courant = max(abs(v_face[i, j, k, 0]), abs(v_face[i1, j, k, 0])) * dt / spacing[0]
    courant += max(abs(v_face[i, j, k, 1]), abs(v_face[i, j1, k, 1])) * dt / spacing[1]
    courant += max(abs(v_face[i, j, k, 2]), abs(v_face[i, j, k + 1, 2])) * dt / spacing[2]
    return courant


@njit(cache=True)
def first_unstable(v_face, p, spacing, dt, courant_limit):
    """First cell (flat C index) with a non-finite pressure (reason 1) or a non-finite velocity
    on one of its faces (reason 2, `component` the axis), or an advective Courant number
    (`_cell_courant`) above courant_limit (reason 3); -1 if none. Returns (cell, reason,
    component, value)."""
    nx, ny, nz = p.shape
    for i in range(nx):
        i1 = i + 1 if i + 1 < nx else 0
        for j in range(ny):
            j1 = j + 1 if j + 1 < ny else 0
            for k in range(nz):
                cell = (i * ny + j) * nz + k
                if not math.isfinite(p[i, j, k]):
                    return cell, 1, -1, p[i, j, k]
                faces = (v_face[i, j, k, 0], v_face[i1, j, k, 0], v_face[i, j, k, 1], v_face[i, j1, k, 1],
                         v_face[i, j, k, 2], v_face[i, j, k + 1, 2])  # fmt: skip
                for n in range(6):
                    if not math.isfinite(faces[n]):
                        return cell, 2, n // 2, faces[n]
                courant = _cell_courant(v_face, i, j, k, spacing, dt)
                if courant > courant_limit:
                    return cell, 3, -1, courant
    return -1, 0, -1, 0.0


@njit(cache=True)
def max_courant(v_face, spacing, dt):
    """Largest advective Courant number of the cells (`_cell_courant`) [-]."""
    nx, ny, nz = v_face.shape[0], v_face.shape[1], v_face.shape[2] - 1
    worst = 0.0
    for i in range(nx):
        for j in range(ny):
            for k in range(nz):
                worst = max(worst, _cell_courant(v_face, i, j, k, spacing, dt))
    return worst
