"""Kernels of the Darcy model's forces on the particles (physics/fluid/darcy.py).

As the original sphere: the pressure-gradient force -V grad p, with grad p (the excess pore
pressure's, physics/fluid/pore_pressure.py) interpolated trilinearly from the cell centres to the
particle centre, and the buoyancy -rho_f V g of the hydrostatic part that p leaves out, on a
particle of volume V = 4/3 pi r^3.

Arguments: pos (N,3) [m], radius (N,) [m], force (N,3) [N]; grad (nx, ny, nz, 3) [Pa/m];
origin, spacing (3,) [m] of the grid; periodic (3,) uint8; rho_f [kg/m^3]; gravity (3,) [m/s^2].
Every particle writes only its own force: results do not depend on the thread count.
"""

import math

from numba import njit, prange


@njit(cache=True, inline="always")
def _corner(x, origin, h, n, periodic):
    """Lower cell index, upper cell index and weight of the upper one for linear interpolation
    between cell centres along one axis (constant beyond the outer centres of a bounded axis)."""
    s = (x - origin) / h - 0.5
    i0 = int(math.floor(s))
    w = s - i0
    if periodic:
        i0 = i0 % n
        return i0, (i0 + 1) % n, w
    if i0 < 0:
        return 0, 0, 0.0
    if i0 >= n - 1:
        return n - 1, n - 1, 0.0
    return i0, i0 + 1, w


@njit(cache=True, parallel=True)
def add_pressure_forces(pos, radius, grad, origin, spacing, periodic, rho_f, gravity, force):
    """force += -V grad p (trilinear in the cell-centred gradient) - rho_f V g."""
    nx, ny, nz = grad.shape[0], grad.shape[1], grad.shape[2]
    for n in prange(pos.shape[0]):
        r = radius[n]
        vol = 4.0 / 3.0 * math.pi * r * r * r
        i0, i1, wx = _corner(pos[n, 0], origin[0], spacing[0], nx, periodic[0])
        j0, j1, wy = _corner(pos[n, 1], origin[1], spacing[1], ny, periodic[1])
        k0, k1, wz = _corner(pos[n, 2], origin[2], spacing[2], nz, 0)
        for a in range(3):
            g = (1.0 - wz) * (
                (1.0 - wy) * ((1.0 - wx) * grad[i0, j0, k0, a] + wx * grad[i1, j0, k0, a])
                + wy * ((1.0 - wx) * grad[i0, j1, k0, a] + wx * grad[i1, j1, k0, a])
            ) + wz * (
                (1.0 - wy) * ((1.0 - wx) * grad[i0, j0, k1, a] + wx * grad[i1, j0, k1, a])
                + wy * ((1.0 - wx) * grad[i0, j1, k1, a] + wx * grad[i1, j1, k1, a])
            )
            force[n, a] += -vol * g - rho_f * vol * gravity[a]
