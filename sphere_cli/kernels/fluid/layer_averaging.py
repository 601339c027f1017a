"""Layer averages of the particles over horizontal slices of the cell (Jackson 2000 with a step
weighting function; Maurin et al. 2015): each sphere contributes to a layer [z_k, z_k+1] the exact
volume of its slice there,

    V_pk = pi [ r^2 s - s^3/3 ] from s_a to s_b,   s = z - z_p clipped to [-r, r],

    solid_k    = sum_p V_pk / (A dz_k)                 solid fraction [-]
    vx_k       = sum_p V_pk vx_p / sum_p V_pk          mean streamwise particle velocity [m/s]
    exchange_k = sum_p (V_pk / V_p) K_p / (A dz_k)     momentum exchange coefficient [kg/(m^3 s)]
    drag_k     = sum_p (V_pk / V_p) fx_p / (A dz_k)    streamwise drag per unit volume [N/m^3]

with A the horizontal area of the cell and K_p the particle's drag coefficient (drag = K_p (u - v)).
The part of a sphere below the first face or above the last one is not counted.

Arguments: pos, vel_p (N,3) [m, m/s] (vx_p = vel_p[:, 0]); radius (N,) [m]; selected (N,) uint8 (1 = counted);
drag_coef (N,) [kg/s]; drag_x (N,) [N]; faces (n+1,) increasing [m]; area [m^2];
outputs solid, vel, exchange, drag (n,) and the scratch volume (n,) [m^3], of the layers
[first, last) (every layer, or an MPI rank's share: physics/fluid/vans1d.py), the others left
as they are.

Serial in the particle order: the sums do not depend on the thread count, and the work
(a few layers per particle, at the coupling interval only) is far below a DEM step's.
"""

import math

from numba import njit


@njit(cache=True, inline="always")
def slice_volume(z_p, r, a, b):
    """Volume of the sphere of centre height z_p and radius r between heights a < b [m^3]."""
    sa = min(max(a - z_p, -r), r)
    sb = min(max(b - z_p, -r), r)
    return math.pi * (r * r * (sb - sa) - (sb * sb * sb - sa * sa * sa) / 3.0)


@njit(cache=True)
def layer_of(faces, z):
    """Index k of the layer faces[k] <= z < faces[k+1], clipped to 0 .. n-1."""
    n = faces.shape[0] - 1
    lo = 0
    hi = n
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if faces[mid] <= z:
            lo = mid
        else:
            hi = mid
    return lo


@njit(cache=True)
def layer_average(
    pos, vel_p, radius, selected, drag_coef, drag_x, faces, area, solid, vel, exchange, drag, volume, first,
    last,
):  # fmt: skip
    n = faces.shape[0] - 1
    for k in range(first, last):
        volume[k] = 0.0
        vel[k] = 0.0
        exchange[k] = 0.0
        drag[k] = 0.0
    for i in range(pos.shape[0]):
        if not selected[i]:
            continue
        z = pos[i, 2]
        r = radius[i]
        if z + r <= faces[0] or z - r >= faces[n]:
            continue
        v_p = 4.0 / 3.0 * math.pi * r * r * r
        for k in range(max(first, layer_of(faces, z - r)), min(last, layer_of(faces, z + r) + 1)):
            vk = slice_volume(z, r, faces[k], faces[k + 1])
            if vk <= 0.0:
                continue
            volume[k] += vk
            vel[k] += vk * vel_p[i, 0]
            exchange[k] += vk / v_p * drag_coef[i]
            drag[k] += vk / v_p * drag_x[i]
    for k in range(first, last):
        layer = area * (faces[k + 1] - faces[k])
        solid[k] = volume[k] / layer
        vel[k] = vel[k] / volume[k] if volume[k] > 0.0 else 0.0
        exchange[k] /= layer
        drag[k] /= layer
