"""Kernels of the Darcy model's forces on the particles (physics/fluid/darcy.py).

The seepage force: without fluid inertia the pore fluid's momentum balance is Darcy's law,
0 = -phi grad p - (drag of the grains on the fluid), so per unit volume of the mixture the fluid
pushes the grains with the drag phi (-grad p) plus the pressure-gradient force (1 - phi)(-grad p)
on their own volume: -grad p in all (Terzaghi's seepage force, i gamma_w per unit volume of
soil). Shared among the grains by volume, a particle of volume V = 4/3 pi r^3 at porosity phi
gets -V grad p / (1 - phi); with it a bed lifts when the pressure drop across it carries its
buoyant weight, and a loaded saturated bed shares the load as sigma = sigma' + p (effective
stress). The original sphere applied -V grad p alone (its `(1 - phi)` factor is commented out),
a (1 - phi) fraction of it: `[fluid] pressure_force = "pressure-gradient"` keeps that for
comparison. grad p (the excess pore pressure's, physics/fluid/pore_pressure.py) and phi (clamped
to [porosity_min, porosity_max]) are interpolated trilinearly from the cell centres to the
particle centre. The buoyancy -rho_f V g of the hydrostatic part that p leaves out is added.

Arguments: pos (N,3) [m], radius (N,) [m], force (N,3) [N]; grad (nx, ny, nz, 3) [Pa/m];
porosity (nx, ny, nz) [-]; whole uint8 (1: divide by 1 - phi, 0: not); origin, spacing (3,)
[m] of the grid; periodic (3,) uint8; rho_f [kg/m^3]; gravity (3,) [m/s^2].
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
        return i0, i0 + 1 if i0 + 1 < n else 0, w  # (a second remainder costs an integer division)
    if i0 < 0:
        return 0, 0, 0.0
    if i0 >= n - 1:
        return n - 1, n - 1, 0.0
    return i0, i0 + 1, w


@njit(cache=True, inline="always")
def _blend(f000, f100, f010, f110, f001, f101, f011, f111, wx, wy, wz):
    """Trilinear interpolation between the values at the eight corners (fxyz: 0 lower, 1 upper)."""
    return (1.0 - wz) * (
        (1.0 - wy) * ((1.0 - wx) * f000 + wx * f100) + wy * ((1.0 - wx) * f010 + wx * f110)
    ) + wz * ((1.0 - wy) * ((1.0 - wx) * f001 + wx * f101) + wy * ((1.0 - wx) * f011 + wx * f111))


@njit(cache=True, inline="always")
def _trilinear(f, i0, i1, j0, j1, k0, k1, wx, wy, wz):
    """Trilinear interpolation of a cell field between the eight corners found by _corner."""
    return _blend(
        f[i0, j0, k0], f[i1, j0, k0], f[i0, j1, k0], f[i1, j1, k0],
        f[i0, j0, k1], f[i1, j0, k1], f[i0, j1, k1], f[i1, j1, k1], wx, wy, wz,
    )  # fmt: skip


@njit(cache=True, inline="always")
def _trilinear_component(f, a, i0, i1, j0, j1, k0, k1, wx, wy, wz):
    """_trilinear of component a of a vector cell field (nx, ny, nz, 3), read in place: a view
    f[:, :, :, a] made for each particle cost a quarter of the force's time."""
    return _blend(
        f[i0, j0, k0, a], f[i1, j0, k0, a], f[i0, j1, k0, a], f[i1, j1, k0, a],
        f[i0, j0, k1, a], f[i1, j0, k1, a], f[i0, j1, k1, a], f[i1, j1, k1, a], wx, wy, wz,
    )  # fmt: skip


@njit(cache=True, inline="always")
def particle_pressure_force(
    n, pos, radius, grad, porosity, whole, origin, spacing, periodic, rho_f, gravity, force
):
    """force[n] += -V grad p / (1 - phi) (whole = 1) or -V grad p (whole = 0), both trilinear in
    the cell fields, and - rho_f V g: one description for the processor's loop
    (add_pressure_forces) and the GPU's threads (kernels/fluid/cuda_darcy.py)."""
    nx, ny, nz = grad.shape[0], grad.shape[1], grad.shape[2]
    r = radius[n]
    vol = 4.0 / 3.0 * math.pi * r * r * r
    i0, i1, wx = _corner(pos[n, 0], origin[0], spacing[0], nx, periodic[0])
    j0, j1, wy = _corner(pos[n, 1], origin[1], spacing[1], ny, periodic[1])
    k0, k1, wz = _corner(pos[n, 2], origin[2], spacing[2], nz, 0)
    share = vol
    if whole:
        share = vol / (1.0 - _trilinear(porosity, i0, i1, j0, j1, k0, k1, wx, wy, wz))
    for a in range(3):
        g = _trilinear_component(grad, a, i0, i1, j0, j1, k0, k1, wx, wy, wz)
        force[n, a] += -share * g - rho_f * vol * gravity[a]


@njit(cache=True, parallel=True)
def add_pressure_forces(pos, radius, grad, porosity, whole, origin, spacing, periodic, rho_f, gravity, force):
    """particle_pressure_force for every particle."""
    for n in prange(pos.shape[0]):
        particle_pressure_force(
            n, pos, radius, grad, porosity, whole, origin, spacing, periodic, rho_f, gravity, force
        )


@njit(cache=True)
def push_wall(coord, top, bottom, height, pressure, stiffness, area, fluid_force):
    """fluid_force[top, 2] = the pore pressure's push on the impermeable top wall `top` at
    coord[top] [m] (physics/fluid/darcy.py Darcy._push_wall): (pressure - moved stiffness) area,
    pressure [Pa] that of the top cells at the last fluid step, moved [m] the wall's rise since
    then above the grid's bottom [m] and its height [m] then, stiffness [Pa/m] the undrained
    response, area [m^2] the grid's top: the processor's and the GPU's (kernels/fluid/
    cuda_darcy.py, one thread)."""
    moved = (coord[top] - bottom) - height
    fluid_force[top, 2] = (pressure - moved * stiffness) * area
