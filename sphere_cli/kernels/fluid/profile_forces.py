"""Fluid forces on spheres from a vertical profile of streamwise fluid velocity u(z) and solid
fraction solid(z) (YADE HydroForceEngine::action; Maurin et al. 2015).

Drag      f_D = K (u(z_p) e_x - v_p),  K = 1/2 rho_f (pi d^2/4) (0.44 |u_r| + 24 nu/d) (1 - solid_p)^-n
          i.e. C_d = (0.44 + 24/Re_p)(1 - solid_p)^-n with Re_p = |u_r| d/nu (Dallavalle 1948,
          Richardson & Zaki 1954); solid_p is capped at solid_max.
Buoyancy  f_B = -rho_f V g (full) or -rho_f V g_z e_z (wall-normal part only, steady flow).
Lift      f_L = 1/2 rho_f C_L (pi d^2/4) (u_r,top^2 - u_r,bottom^2) e_z, u_r = u - v_x taken at the
          top and the bottom of the sphere (Wiberg & Smith 1985).
All three scale with the submerged fraction of the sphere (the part below the surface).

The profiles live at the layer centres; between centres they are linear. Below the first centre
u goes linearly to 0 at the bottom (no-slip); above the last centre it is constant (free surface)
or goes linearly to 0 at the lid (no-slip top). solid is constant beyond the end centres.

Arguments: pos, vel (N,3) [m, m/s]; radius (N,) [m]; selected (N,) uint8; faces (n+1,) [m];
centres (n,) [m]; u (n,) [m/s]; solid (n,) [-]; top_no_slip (bool); lid_velocity [m/s] of a
no-slip lid; rho [kg/m^3]; nu [m^2/s];
exponent n [-]; solid_max [-]; gravity (3,) [m/s^2]; buoyancy_full (bool); lift_coef [-];
fluct (N,3) [m/s] turbulent fluctuations added to the fluid velocity each particle sees, read
only where `fluctuating` (kernels/fluid/turbulent_fluctuations.py; else any array);
force (N,3) [N] (added to); drag_coef (N,) [kg/s] and drag_x (N,) [N] (written).
"""

import math

from numba import njit, prange

from ..rank_messages import rank_dem_steps, rank_dem_steps_serial
from ..serial import serial_twin, variant
from ..steps import dem_steps, dem_steps_serial
from .layer_averaging import slice_volume


@njit(cache=True, inline="always")
def bracket(centres, z):
    """(lo, hi, w): z lies between centres[lo] and centres[hi] at the fraction w; lo = hi and
    w = 0 beyond the first or the last centre."""
    n = centres.shape[0]
    if z <= centres[0]:
        return 0, 0, 0.0
    if z >= centres[n - 1]:
        return n - 1, n - 1, 0.0
    # Start from the layer z would be in if the centres were evenly spaced (they are unless the
    # layers are stretched): two comparisons confirm it, instead of ~log2(n) hard-to-predict
    # branches. The bracket is unique (centres[lo] <= z < centres[lo + 1]), so the result is the
    # plain bisection's whatever the guess.
    lo = 0
    hi = n - 1
    guess = min(max(int((z - centres[0]) / (centres[n - 1] - centres[0]) * (n - 1)), 0), n - 2)
    if centres[guess] <= z:
        lo = guess
    else:
        hi = guess
    if centres[guess + 1] > z:
        hi = min(hi, guess + 1)
    else:
        lo = max(lo, guess + 1)
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if centres[mid] <= z:
            lo = mid
        else:
            hi = mid
    return lo, hi, (z - centres[lo]) / (centres[hi] - centres[lo])


@njit(cache=True, inline="always")
def _velocity(faces, centres, u, top_no_slip, lid_velocity, z, lo, hi, w):
    """u(z) given z's bracket, with the boundary conditions: 0 at and below the bottom, and
    lid_velocity [m/s] at and above a no-slip lid."""
    n = centres.shape[0]
    if z < centres[0]:
        bottom = faces[0]
        return u[0] * (z - bottom) / (centres[0] - bottom) if z > bottom else 0.0
    if z > centres[n - 1] and top_no_slip:
        top = faces[n]
        if z >= top:
            return lid_velocity
        return u[n - 1] + (lid_velocity - u[n - 1]) * (z - centres[n - 1]) / (top - centres[n - 1])
    return (1.0 - w) * u[lo] + w * u[hi]


@njit(cache=True, inline="always")
def fluid_velocity_at(faces, centres, u, top_no_slip, lid_velocity, z):
    """u(z) with the boundary conditions (see _velocity)."""
    lo, hi, w = bracket(centres, z)
    return _velocity(faces, centres, u, top_no_slip, lid_velocity, z, lo, hi, w)


@njit(cache=True, inline="always")
def _drag_coefficient(rho, nu, r, speed, solid_p, exponent, solid_max):
    hindrance = (1.0 - min(max(solid_p, 0.0), solid_max)) ** (-exponent)
    return 0.5 * rho * math.pi * r * r * (0.44 * speed + 12.0 * nu / r) * hindrance


@njit(cache=True, inline="always")
def particle_profile_force(
    i, pos, vel, radius, selected, faces, centres, u, solid, top_no_slip, lid_velocity, rho, nu, exponent,
    solid_max, gravity, buoyancy_full, lift_coef, fluctuating, fluct, force, drag_coef, drag_x,
):  # fmt: skip
    """The fluid's force on particle i (module docstring), added to force[i]; its drag
    coefficient and streamwise drag into drag_coef[i], drag_x[i]. One description for the
    processor's loop (profile_forces) and the GPU's threads (kernels/fluid/cuda_profile_forces.py)."""
    drag_coef[i] = 0.0
    drag_x[i] = 0.0
    if not selected[i]:
        return
    top = faces[centres.shape[0]]
    z = pos[i, 2]
    r = radius[i]
    volume = 4.0 / 3.0 * math.pi * r * r * r
    submerged = slice_volume(z, r, z - r, top)
    if submerged <= 0.0:
        return
    frac = submerged / volume
    lo, hi, w = bracket(centres, z)
    ur = _velocity(faces, centres, u, top_no_slip, lid_velocity, z, lo, hi, w) - vel[i, 0]
    vr = -vel[i, 1]
    wr = -vel[i, 2]
    if fluctuating:
        ur += fluct[i, 0]
        vr += fluct[i, 1]
        wr += fluct[i, 2]
    speed = math.sqrt(ur * ur + vr * vr + wr * wr)
    solid_p = (1.0 - w) * solid[lo] + w * solid[hi]
    k = frac * _drag_coefficient(rho, nu, r, speed, solid_p, exponent, solid_max)
    drag_coef[i] = k
    drag_x[i] = k * ur
    force[i, 0] += k * ur
    force[i, 1] += k * vr
    force[i, 2] += k * wr
    if buoyancy_full:
        force[i, 0] -= rho * submerged * gravity[0]
        force[i, 1] -= rho * submerged * gravity[1]
    force[i, 2] -= rho * submerged * gravity[2]
    if lift_coef > 0.0:
        u_top = fluid_velocity_at(faces, centres, u, top_no_slip, lid_velocity, z + r) - vel[i, 0]
        u_bottom = fluid_velocity_at(faces, centres, u, top_no_slip, lid_velocity, z - r) - vel[i, 0]
        force[i, 2] += frac * 0.5 * rho * lift_coef * math.pi * r * r * (u_top * u_top - u_bottom * u_bottom)


@njit(cache=True, parallel=True)
def profile_forces(
    pos,
    vel,
    radius,
    selected,
    faces,
    centres,
    u,
    solid,
    top_no_slip,
    lid_velocity,
    rho,
    nu,
    exponent,
    solid_max,
    gravity,
    buoyancy_full,
    lift_coef,
    fluctuating,
    fluct,
    force,
    drag_coef,
    drag_x,
):
    for i in prange(pos.shape[0]):
        particle_profile_force(
            i, pos, vel, radius, selected, faces, centres, u, solid, top_no_slip, lid_velocity, rho, nu,
            exponent, solid_max, gravity, buoyancy_full, lift_coef, fluctuating, fluct, force, drag_coef,
            drag_x,
        )  # fmt: skip


@njit(cache=True, parallel=True)
def drag_coefficients(
    pos,
    vel,
    radius,
    selected,
    faces,
    centres,
    u,
    solid,
    top_no_slip,
    lid_velocity,
    rho,
    nu,
    exponent,
    solid_max,
    drag_coef,
    drag_x,
):
    """K_p and the streamwise drag K_p u_r of each particle, without touching the forces."""
    n = centres.shape[0]
    top = faces[n]
    for i in prange(pos.shape[0]):
        drag_coef[i] = 0.0
        drag_x[i] = 0.0
        if not selected[i]:
            continue
        z = pos[i, 2]
        r = radius[i]
        submerged = slice_volume(z, r, z - r, top)
        if submerged <= 0.0:
            continue
        frac = submerged / (4.0 / 3.0 * math.pi * r * r * r)
        lo, hi, w = bracket(centres, z)
        ur = _velocity(faces, centres, u, top_no_slip, lid_velocity, z, lo, hi, w) - vel[i, 0]
        speed = math.sqrt(ur * ur + vel[i, 1] * vel[i, 1] + vel[i, 2] * vel[i, 2])
        solid_p = (1.0 - w) * solid[lo] + w * solid[hi]
        k = frac * _drag_coefficient(rho, nu, r, speed, solid_p, exponent, solid_max)
        drag_coef[i] = k
        drag_x[i] = k * ur


# one thread: the same kernel without a parallel region (kernels/serial.py)
profile_forces_serial = serial_twin(profile_forces, distinct=True)  # arrays of their own

# the compiled loops with this force in the place they leave for a fluid's (kernels/steps.py
# fluid_force), on one rank and on MPI ranks, and their twins for one thread
vans1d_steps = variant(dem_steps, "vans1d", fluid_force=profile_forces)
vans1d_steps_serial = variant(dem_steps_serial, "vans1d", fluid_force=profile_forces_serial)
rank_vans1d_steps = variant(rank_dem_steps, "vans1d", fluid_force=profile_forces)
rank_vans1d_steps_serial = variant(rank_dem_steps_serial, "vans1d", fluid_force=profile_forces_serial)
