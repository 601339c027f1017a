"""Fluid-particle drag: the drag laws, the particles' semi-implicit velocity update, and the
equal and opposite momentum exchange gathered per fluid cell.

Drag on particle i of diameter d, volume V = pi d^3/6 and velocity v in a cell of porosity phi
and fluid velocity u:  F_i = V k (u - v) = K_i (u - v),  k [kg/(m^3 s)] from `drag_rate`:
- Gidaspow (1994), k = beta/(1 - phi) with beta the interphase momentum exchange coefficient
  (force per mixture volume per relative velocity):
    phi <= 0.8, Ergun (1952):  beta = 150 mu (1-phi)^2/(phi d^2) + 1.75 rho (1-phi) |u-v|/d
    phi >  0.8, Wen & Yu (1966):  beta = 3/4 C_d phi (1-phi) rho |u-v|/d phi^-2.65
  with Re = phi rho d |u-v|/mu and the Schiller-Naumann C_d = 24/Re (1 + 0.15 Re^0.687),
  0.44 for Re >= 1000. (The sphere documentation prints the Wen-Yu line with an extra mu_f
  and without the leading phi; this is the dimensionally consistent Gidaspow form.) The
  switch at phi = 0.8 is not continuous: at Re -> 0 Ergun is 1.153 times Wen-Yu there. As
  phi -> 1, V k -> 3 pi mu d (1 + 0.15 Re^0.687), the drag of an isolated sphere.
- Di Felice (1994), the law of the original CUDA code of sphere:
    F = 1/2 C_d rho (pi d^2/4) phi^2 |u-v| (u-v) phi^-chi,   C_d = (0.63 + 4.8/sqrt(Re))^2,
    chi = 3.7 - 0.65 exp(-(1.5 - log10 Re)^2/2),  so  k = 3/4 C_d rho |u-v| phi^(2-chi)/d.
C_d |u-v| is formed without dividing by |u-v|, so k is finite at zero relative velocity.
Porosity enters as max(phi, floor) (Ergun diverges as phi -> 0), capped at 1.

Velocity update (replaces the second half kick of velocity Verlet, kernels/motion.py). Over a
half step h = dt/2 with the other forces F_o and the fluid velocity frozen, dv/dt = F_o/m +
lambda (u - v), lambda = K/m, has the exact solution
    v(h) = v + h phi1(lambda h) (F_o/m + lambda (u - v)),   phi1(x) = (1 - e^-x)/x,
stable and exact at the terminal velocity u + F_o/K for any lambda dt (tau_p = 1/lambda may be
far below dt). The force stored for the next first half kick is the one that makes that kick
this same exact update:  F_drag = phi1 K (u - v) + (phi1 - 1) F_o  (-> K (u - v) as
lambda h -> 0).

Momentum exchange. Each particle accumulates the drag impulse J its two half kicks gave it. A
fluid step of length dt_f takes the drag its cell's particles will receive over the next
interval, implicitly in its own new velocity u': over that interval, with u' and the other
forces F_o frozen, the exact relaxation above gives the particle the mean drag
    phi1(lambda dt_f) K (u' - v) + (phi1 - 1) F_o,
linear in u' with the slope phi1 K (K when lambda dt_f << 1; m/dt_f, the inertia of a particle
carried along, when >> 1). Per cell the fluid step therefore takes f_i + k_drag (u' - u), with
f_i that sum at the fluid velocity u now over the cell volume and k_drag = sum phi1 K / V_cell:
a bed held in place (1/m = 0) is fully implicit and stable at any drag relaxation time. What the
particles then actually receive (their DEM steps differ from the frozen prediction) is settled
with the next fluid step: its f_i adds the impulses received, sum J / (V_cell dt_f), and
subtracts what the last step took for that interval (the old prediction and f_exchange - f_i).
Over any number of steps the fluid receives exactly minus what the particles received, up to
the one pending interval. Gathered per cell in particle order: bitwise independent of the
thread count.

Arrays: vel, force, f_other, f_drag (N,3) [m, m/s, N, N, N]; impulse (N,3) [N s] the drag
impulse since the last fluid step; radius, inv_mass (N,) [m, 1/kg];
coef (N,) [kg/s] the particle's K; cell_of (N,) int64 flat index (ix ny + iy) nz + iz of its
fluid cell; fluid arrays flattened over cells: u (C,3) [m/s], phi (C,) [-], grad_p (C,3) [Pa/m],
f_i (C,3) [N/m^3] force density of the fluid on the particles, f_i_coef (C,) [kg/(m^3 s)],
f_exchange (C,3) [N/m^3] what the last fluid step took, f_i + f_i_coef (u_new - u); predicted
(C,3) [N/m^3] the drag the particles of each cell were expected to receive over the interval
since the last fluid step.
"""

import math

import numpy as np
from numba import njit, prange

from ..motion import kick_drift, kick_drift_serial
from ..rank_messages import (
    rank_drift,
    rank_drift_serial,
    rank_walls_kick,
    seconds,
    send_ghost_forces,
)
from ..serial import serial_twin
from ..steps import contacts, contacts_serial, walls_kick, walls_moved
from ..walls import wall_kick_drift
from .porosity import bin_particles, bin_particles_serial

GIDASPOW = 0
DI_FELICE = 1
ERGUN_POROSITY = 0.8  # Gidaspow: Ergun at or below, Wen-Yu above
GAIN_CAP = 0.5  # largest share of its own drag a particle's self-induced velocity may take back
BANDS = 6  # the bands of each particle's self-induced velocity (physics/fluid/self_induced.py MODES)


@njit(cache=True, inline="always")
def drag_rate(law, phi, d, w, rho, mu, floor):
    """k [kg/(m^3 s)] of a sphere of diameter d [m] at relative speed w [m/s] in porosity phi,
    fluid density rho [kg/m^3] and viscosity mu [Pa s]: drag = (pi d^3/6) k (u - v)."""
    phi = min(max(phi, floor), 1.0)
    re = phi * rho * d * w / mu
    if law == GIDASPOW:
        if phi <= ERGUN_POROSITY:
            return 150.0 * mu * (1.0 - phi) / (phi * d * d) + 1.75 * rho * w / d
        if re < 1000.0:
            cd_w = 24.0 * mu / (phi * rho * d) * (1.0 + 0.15 * re**0.687)
        else:
            cd_w = 0.44 * w
        return 0.75 * cd_w * rho * phi**-1.65 / d
    chi = 3.7
    if re > 0.0:
        chi -= 0.65 * math.exp(-0.5 * (1.5 - math.log10(re)) ** 2)
    root = 0.63 * math.sqrt(w) + 4.8 * math.sqrt(mu / (phi * rho * d))  # sqrt(C_d w)
    return 0.75 * root * root * rho * phi ** (2.0 - chi) / d


@njit(cache=True, inline="always")
def phi1(x):
    """(1 - e^-x)/x for x >= 0, 1 at 0."""
    if x < 1e-12:
        return 1.0 - 0.5 * x
    return -math.expm1(-x) / x


@njit(cache=True, parallel=True)
def particle_drag(
    law,
    rho,
    mu,
    floor,
    pressure_force,
    cell_of,
    vel,
    radius,
    inv_mass,
    u,
    phi,
    grad_p,
    dt,
    initial,
    cell_share,
    cell_diameter,
    cell_velocity,
    disturbance,
    force,
    f_other,
    coef,
    f_drag,
):
    """Forces phase: add the pressure-gradient force -V grad(p) (if pressure_force) and the drag
    to `force` (which holds every other force); keep the non-drag force in f_other and K in coef
    for the kick. `initial` (the forces of the initial state): also keep the drag in f_drag, for
    the first half kick (later the kick sets it). Returns the number of particles in cells below
    the porosity floor.

    The cell-averaged drag (cell_share (C,) not empty): K = V cell_share k(phi, d_c, |u - v_c|)
    with the cell's mean diameter d_c = cell_diameter [m] and velocity v_c = cell_velocity [m/s],
    cell_share = (1 - phi) V_cell / (the volume of the particles centred in it), so that the
    cell's particles together receive (1 - phi) V_cell k (u - v_c) (by their volume-weighted mean
    velocity); a cell no particle reaches (d_c = 0), or where none was centred at the last fluid
    step (cell_share 0: a particle that has just moved in), falls back to the particle's own.
    disturbance (N,3,MODES) [m/s] (or empty): the bands of each particle's self-induced velocity
    u' (physics/fluid/self_induced.py), which it does not feel: it sees the fluid velocity u -
    u', u' the sum over the bands."""
    below = 0
    for i in prange(vel.shape[0]):
        below += drag_on_particle(
            i, law, rho, mu, floor, pressure_force, cell_of, vel, radius, inv_mass, u, phi, grad_p, dt,
            initial, cell_share, cell_diameter, cell_velocity, disturbance, force, f_other, coef, f_drag,
        )  # fmt: skip
    return below


@njit(cache=True, inline="always")
def drag_on_particle(
    i, law, rho, mu, floor, pressure_force, cell_of, vel, radius, inv_mass, u, phi, grad_p, dt, initial,
    cell_share, cell_diameter, cell_velocity, disturbance, force, f_other, coef, f_drag,
):  # fmt: skip
    """particle_drag for particle i (also the GPU's, kernels/fluid/cuda_drag.py): 1 if its cell
    is below the porosity floor, else 0."""
    half = 0.5 * dt
    averaged = cell_share.shape[0] > 0
    corrected = disturbance.shape[0] > 0
    c = cell_of[i]
    d = 2.0 * radius[i]
    volume = math.pi / 6.0 * d * d * d
    # the fluid velocity the particle feels, summed over its disturbance's bands once
    seen = (
        _seen(u, c, disturbance, i, 0, corrected),
        _seen(u, c, disturbance, i, 1, corrected),
        _seen(u, c, disturbance, i, 2, corrected),
    )
    if averaged and cell_diameter[c] > 0.0 and cell_share[c] > 0.0:
        w0 = u[c, 0] - cell_velocity[c, 0]
        w1 = u[c, 1] - cell_velocity[c, 1]
        w2 = u[c, 2] - cell_velocity[c, 2]
        w = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
        k = volume * cell_share[c] * drag_rate(law, phi[c], cell_diameter[c], w, rho, mu, floor)
    else:
        w0 = seen[0] - vel[i, 0]
        w1 = seen[1] - vel[i, 1]
        w2 = seen[2] - vel[i, 2]
        k = volume * drag_rate(law, phi[c], d, math.sqrt(w0 * w0 + w1 * w1 + w2 * w2), rho, mu, floor)
    coef[i] = k
    g = phi1(k * inv_mass[i] * half)
    for a in range(3):
        fo = force[i, a]
        if pressure_force:
            fo -= volume * grad_p[c, a]
        fd = g * k * (seen[a] - vel[i, a]) + (g - 1.0) * fo
        f_other[i, a] = fo
        if initial:
            f_drag[i, a] = fd
        force[i, a] = fo + fd
    return 1 if phi[c] < floor else 0


@njit(cache=True, parallel=True)
def drag_kick(
    vel, angvel, torque, inv_mass, inv_inertia, cell_of, u, coef, f_other, dt, force, f_drag, impulse,
    disturbance, cell_coef, cell_volume, weight, rate, band_decay, mu, nu,
):  # fmt: skip
    """Second half kick, exact for the drag at frozen K, u - u' and other forces (see the module
    docstring); then the drag force that makes the next first half kick exact too. The drag
    impulse of both half kicks of this step is added to `impulse`.

    With `disturbance` (N,3,MODES) not empty, each band j of each particle's self-induced
    velocity then follows the mean drag F of the step over dt (physics/fluid/self_induced.py),
    exactly for F held: for component a, with the band's weight W = weight[a, j] [1/m] and rate
    lambda = rate[a, j] [1/m^2], the other particles' drag coefficients S = cell_coef[cell] - K
    (cell_coef (C,) [kg/s] the sum of K over the particles of each cell, `cell_coefficients`),
    kappa^2 = S/(mu V_cell), s = lambda/(lambda + kappa^2):
        u'_j <- u'_inf + (u'_j - u'_inf) exp(-nu (lambda + kappa^2) dt),
        u'_inf = -c W s^2 F/mu;  mu [Pa s], nu [m^2/s] of the fluid; band_decay[a, j] =
    exp(-nu lambda dt), the decay of a band without screening over this dt. c = 1, or less where
    the particle's own loop gain G = K sum_j W s^2/mu (the share of its drag it would take back
    from its own wake) exceeds GAIN_CAP: c = GAIN_CAP/G keeps the corrected drag K/(1 - c G)
    bounded for particles nearly as wide as their cell."""
    for i in prange(vel.shape[0]):
        kick_with_drag(
            i, vel, angvel, torque, inv_mass, inv_inertia, cell_of, u, coef, f_other, dt, force, f_drag,
            impulse, disturbance, cell_coef, cell_volume, weight, rate, band_decay, mu, nu,
        )  # fmt: skip


@njit(cache=True, inline="always")
def kick_with_drag(
    i, vel, angvel, torque, inv_mass, inv_inertia, cell_of, u, coef, f_other, dt, force, f_drag, impulse,
    disturbance, cell_coef, cell_volume, weight, rate, band_decay, mu, nu,
):  # fmt: skip
    """drag_kick for particle i (also the GPU's, kernels/fluid/cuda_drag.py)."""
    half = 0.5 * dt
    corrected = disturbance.shape[0] > 0
    c = cell_of[i]
    k = coef[i]
    im = inv_mass[i]
    g = phi1(k * im * half)
    screening = 0.0
    screen_decay = 1.0
    if corrected:
        screening = max(cell_coef[c] - k, 0.0) / (mu * cell_volume)
        if screening > 0.0:
            screen_decay = math.exp(-nu * screening * dt)
    for a in range(3):
        fo = f_other[i, a]
        seen = _seen(u, c, disturbance, i, a, corrected)  # its bands change only at the end
        now = g * k * (seen - vel[i, a]) + (g - 1.0) * fo
        mean_drag = 0.5 * (f_drag[i, a] + now)  # over the step: this half kick's and the first's
        impulse[i, a] += dt * mean_drag
        vel[i, a] += half * (fo + now) * im
        fd = g * k * (seen - vel[i, a]) + (g - 1.0) * fo
        f_drag[i, a] = fd
        force[i, a] = fo + fd
        angvel[i, a] += half * torque[i, a] * inv_inertia[i]
        if corrected:
            screened = _screened_weights(weight, rate, a, screening)  # each band's W s^2, once
            gain = 0.0
            for j in range(BANDS):
                gain += screened[j]
            gain *= k / mu
            mobility = mean_drag / mu
            if gain > GAIN_CAP:
                mobility *= GAIN_CAP / gain
            for j in range(BANDS):
                target = -screened[j] * mobility
                decay = band_decay[a, j] * screen_decay
                disturbance[i, a, j] = target + (disturbance[i, a, j] - target) * decay


@njit(cache=True, inline="always")
def _screened_weight(weight, rate, a, j, screening):
    """W s^2 of band j of component a, s = lambda/(lambda + kappa^2) (drag_kick)."""
    share = rate[a, j] / (rate[a, j] + screening)
    return weight[a, j] * share * share


@njit(cache=True, inline="always")
def _screened_weights(weight, rate, a, screening):
    """_screened_weight of the BANDS bands of component a, as a tuple: the kick reads each
    twice, and its division is most of the kick's cost."""
    return (
        _screened_weight(weight, rate, a, 0, screening),
        _screened_weight(weight, rate, a, 1, screening),
        _screened_weight(weight, rate, a, 2, screening),
        _screened_weight(weight, rate, a, 3, screening),
        _screened_weight(weight, rate, a, 4, screening),
        _screened_weight(weight, rate, a, 5, screening),
    )


@njit(cache=True)
def cell_coefficients(cell_of, coef, out):
    """out (C,) = the sum of the drag coefficients coef (N,) [kg/s] of the particles of each cell,
    in particle order (serial: independent of the thread count)."""
    for c in range(out.shape[0]):
        out[c] = 0.0
    for i in range(coef.shape[0]):
        out[cell_of[i]] += coef[i]


@njit(cache=True)
def rank_cell_coefficients(cell_of, coef, out, own, table, merge, merged_cell, merged_coef, mail, mpi):
    """cell_coefficients on an MPI rank, as one rank sums them (physics/fluid/drag.py
    plan_exchange): each rank's own particles' (cell, coefficient) go to the ranks whose
    particles can visit their cells until the next list build (mail, kernels/rank_messages.py
    send_ghost_forces's, two doubles a particle); each rank sums its own and those received in
    global order (merge: the rows of table, (held + received, 2), in ascending global index).
    Every cell the rank's particles can be in gets the sum over every rank's particles in it.
    Returns MPI's first error code (0: none)."""
    for i in own:
        table[i, 0] = cell_of[i]  # a cell's index as a double: exact below 2^53
        table[i, 1] = coef[i]
    code = send_ghost_forces(table, table[:, :0], table[:, :0], mpi, mail)
    if code != 0:
        return code
    merged_rows(table, merge, merged_cell, merged_coef)
    cell_coefficients(merged_cell, merged_coef, out)
    return 0


@njit(cache=True)
def merged_rows(table, merge, merged_cell, merged_coef):
    """The (cell, coefficient) rows merge of table, in that order (rank_cell_coefficients)."""
    for m in range(merge.shape[0]):
        r = merge[m]
        merged_cell[m] = np.int64(table[r, 0])
        merged_coef[m] = table[r, 1]


@njit(cache=True, inline="always")
def _seen(u, c, disturbance, i, a, corrected):
    """Component a of the fluid velocity particle i feels in its cell c: the cell's, less the
    particle's own disturbance of it where `corrected`."""
    if corrected:
        own = 0.0
        for j in range(disturbance.shape[2]):
            own += disturbance[i, a, j]
        return u[c, a] - own
    return u[c, a]


@njit(cache=True, parallel=True)
def exchange(
    first,
    last,
    start,
    order,
    impulse,
    coef,
    inv_mass,
    f_other,
    vel,
    radius,
    u,
    grad_p,
    pressure_exchanged,
    fluid_dt,
    inv_cell_volume,
    disturbance,
    f_i,
    f_i_coef,
    f_exchange,
    predicted,
    solid,
):
    """Per cell c of [first, last) (flat indices: every cell, or a rank's slab of x planes), in
    particle order (module docstring, "Momentum exchange"): `predicted` = the drag its particles
    will receive over the next fluid interval at the fluid velocity u now, sum
    (phi1 K (u - v) + (phi1 - 1) F_o) / cell volume; f_i = that, plus the drag impulses received
    over the last interval / (fluid_dt cell volume) less what the last fluid step took for them
    (its implicit part f_exchange - f_i and the old `predicted`), plus -V grad(p) / cell volume if
    pressure_exchanged; f_i_coef = sum phi1 K / cell volume, phi1 = phi1(lambda fluid_dt); solid
    the volume of the particles centred in each cell [m^3]. The impulses of those cells'
    particles are reset to zero. With disturbance (N,3,MODES) not empty the particles feel
    u - u' (`particle_drag`)."""
    for c in prange(first, last):
        exchange_cell(
            c, start, order, impulse, coef, inv_mass, f_other, vel, radius, u, grad_p, pressure_exchanged,
            fluid_dt, inv_cell_volume, disturbance, f_i, f_i_coef, f_exchange, predicted, solid,
        )  # fmt: skip


@njit(cache=True, inline="always")
def exchange_cell(
    c, start, order, impulse, coef, inv_mass, f_other, vel, radius, u, grad_p, pressure_exchanged, fluid_dt,
    inv_cell_volume, disturbance, f_i, f_i_coef, f_exchange, predicted, solid,
):  # fmt: skip
    """exchange for cell c (also the GPU's, kernels/fluid/cuda_drag.py)."""
    inv_dt = 1.0 / fluid_dt
    corrected = disturbance.shape[0] > 0
    r0 = r1 = r2 = 0.0  # drag impulses received
    e0 = e1 = e2 = 0.0  # drag expected over the next interval
    sk = 0.0
    sv = 0.0
    for j in range(start[c], start[c + 1]):
        i = order[j]
        g = phi1(coef[i] * inv_mass[i] * fluid_dt)
        k = g * coef[i]
        sk += k
        r0 += impulse[i, 0]
        r1 += impulse[i, 1]
        r2 += impulse[i, 2]
        impulse[i, 0] = 0.0
        impulse[i, 1] = 0.0
        impulse[i, 2] = 0.0
        e0 += k * (_seen(u, c, disturbance, i, 0, corrected) - vel[i, 0]) + (g - 1.0) * f_other[i, 0]
        e1 += k * (_seen(u, c, disturbance, i, 1, corrected) - vel[i, 1]) + (g - 1.0) * f_other[i, 1]
        e2 += k * (_seen(u, c, disturbance, i, 2, corrected) - vel[i, 2]) + (g - 1.0) * f_other[i, 2]
        d = 2.0 * radius[i]
        sv += math.pi / 6.0 * d * d * d
    _settle(c, 0, r0, e0, sv, inv_dt, inv_cell_volume, grad_p, pressure_exchanged, f_i, f_exchange, predicted)
    _settle(c, 1, r1, e1, sv, inv_dt, inv_cell_volume, grad_p, pressure_exchanged, f_i, f_exchange, predicted)
    _settle(c, 2, r2, e2, sv, inv_dt, inv_cell_volume, grad_p, pressure_exchanged, f_i, f_exchange, predicted)
    f_i_coef[c] = sk * inv_cell_volume
    solid[c] = sv


@njit(cache=True, inline="always")
def _settle(
    c, a, received, expected, solid, inv_dt, inv_cell_volume, grad_p, pressure_exchanged, f_i, f_exchange,
    predicted,
):  # fmt: skip
    """Component a of cell c's f_i: the new prediction, plus what the particles received over the
    last interval less what the last fluid step took for it (its implicit part f_exchange - f_i
    and the old prediction), plus -V grad(p) if pressure_exchanged; the new prediction kept."""
    took = f_exchange[c, a] - f_i[c, a] + predicted[c, a]
    predicted[c, a] = expected * inv_cell_volume
    f_i[c, a] = predicted[c, a] + received * inv_dt * inv_cell_volume - took
    if pressure_exchanged:
        f_i[c, a] -= solid * grad_p[c, a] * inv_cell_volume


@njit(cache=True, parallel=True)
def cell_shares(phi, solid, inv_cell_volume, share):
    """share = (1 - phi) V_cell / solid of every cell, the cell-averaged drag's share of a
    particle's volume (solid [m^3] the volume of the particles centred in the cell); 0 where none
    is."""
    for c in prange(share.shape[0]):
        share[c] = (1.0 - phi[c]) / (inv_cell_volume * solid[c]) if solid[c] > 0.0 else 0.0


@njit(cache=True, parallel=True)
def cell_drag(law, rho, mu, floor, u, phi, diameter, vp, grad_p, pressure_exchanged, f_i, f_i_coef):
    """The cell-averaged form of the sphere documentation, for a bed given by its porosity, mean
    diameter diameter (C,) [m] and mean particle velocity vp (C,3) [m/s] alone (no particles
    receive it): f_i = (1 - phi) k (u - vp) (minus (1 - phi) grad(p) if pressure_exchanged),
    f_i_coef = (1 - phi) k, so that the fluid step takes f_i + f_i_coef (u_new - u) = (1 - phi) k
    (u_new - vp): implicit in the fluid velocity, stable at any drag relaxation time. Cells with
    phi >= 1 hold no solid and get zero."""
    for c in prange(f_i_coef.shape[0]):
        solid = 1.0 - phi[c]
        if solid <= 0.0:
            f_i_coef[c] = 0.0
            f_i[c, 0] = 0.0
            f_i[c, 1] = 0.0
            f_i[c, 2] = 0.0
            continue
        w0 = u[c, 0] - vp[c, 0]
        w1 = u[c, 1] - vp[c, 1]
        w2 = u[c, 2] - vp[c, 2]
        w = math.sqrt(w0 * w0 + w1 * w1 + w2 * w2)
        beta = solid * drag_rate(law, phi[c], diameter[c], w, rho, mu, floor)
        f_i_coef[c] = beta
        f_i[c, 0] = beta * w0
        f_i[c, 1] = beta * w1
        f_i[c, 2] = beta * w2
        if pressure_exchanged:
            f_i[c, 0] -= solid * grad_p[c, 0]
            f_i[c, 1] -= solid * grad_p[c, 1]
            f_i[c, 2] -= solid * grad_p[c, 2]


@njit(cache=True)
def coefficients_if_any(coefficients):
    """cell_coefficients with the argument tuple `coefficients`, or nothing for None (an argument,
    so that Numba leaves out the branch its type rules out)."""
    if coefficients is not None:
        cell_coefficients(*coefficients)


@njit(cache=True)
def rank_coefficients_if_any(coefficients, mpi):
    """rank_cell_coefficients with the argument tuple `coefficients` and mpi, or 0 (no error)
    for None, as coefficients_if_any."""
    if coefficients is not None:
        return rank_cell_coefficients(*coefficients, mpi)
    return 0


@njit(cache=True)
def drag_steps(steps, threshold2, drift, cross, pairs, walls, drag, kicks, motion):
    """kernels/steps.py dem_steps with the Navier-Stokes drag, in the order of its hooks
    (physics/fluid/drag.py): after the contacts the particles are binned into the fluid's cells
    and given the drag (bin_particles, particle_drag), and drag_kick takes the kick's place
    (`kicks` its arguments), after the sums of each cell's drag coefficients where the
    self-induced velocity is subtracted. drag = (the arguments of bin_particles, of
    particle_drag, of cell_coefficients or None, below (1,) int64, stop): the particles found
    under the porosity floor by the last step that found any are written to below[0], and with
    `stop` the loop returns after that step (the caller warns of it at its step). motion: None
    where no wall moves, else dem_steps's: the walls move before the particles drift and are
    kicked after the drag (whose force on a glued sphere their totals read), before the
    particles."""
    binning, forces, coefficients, below, stop = drag
    moved2 = 0.0
    for done in range(steps):
        if motion is not None:
            wall_kick_drift(*motion[0])
        moved2 = kick_drift(*drift, False)
        if moved2 > threshold2:
            return done, moved2, True
        if motion is not None and walls_moved(motion[0][4], motion[4], motion[5]):
            return done, moved2, True
        contacts(cross, pairs, walls)
        bin_particles(*binning)
        count = particle_drag(*forces)
        walls_kick(motion, done)
        coefficients_if_any(coefficients)
        drag_kick(*kicks)
        if count:
            below[0] = count
            if stop:
                return done + 1, moved2, False
    return steps, moved2, False


@njit(cache=True)
def rank_drag_steps(
    steps, step, threshold2, drift, cross, pairs, walls, drag, kicks, motion, mpi, mail, scratch
):
    """drag_steps on an MPI rank's part, with the returns, the messages and the walls' motion of
    kernels/rank_messages.py rank_dem_steps (`drag` and `kicks` are drag_steps's, `motion`
    rank_dem_steps's; no energy budget): after the drag, each owner sends its ghosts' force and
    torque and their other forces (f_other, drag_kick's 9th argument), which their drag kick
    reads, so every ghost is kicked as its owner; the walls are kicked from their totals over
    every rank. Where the self-induced velocity is subtracted, `coefficients` are
    rank_cell_coefficients's arguments but mpi (physics/fluid/drag.py loop_arguments): each
    cell's drag coefficients summed over every rank's particles, as one rank sums them, before
    the particles' kick (None where it is kept)."""
    binning, forces, coefficients, below, stop = drag
    moved, clock = scratch
    mine, largest = moved[:1], moved[1:]
    busy = 0.0
    force, torque, others = kicks[10], kicks[2], kicks[8]
    for done in range(steps):
        code, stale = rank_drift(motion, drift, mpi, mine, largest, threshold2, False)
        if code != 0 or stale:
            return done, largest[0], stale, busy, code
        started = seconds(mpi, clock)
        contacts(cross, pairs, walls)
        bin_particles(*binning)
        count = particle_drag(*forces)
        busy += seconds(mpi, clock) - started
        code = send_ghost_forces(force, torque, others, mpi, mail)
        if code != 0:
            return done, largest[0], False, busy, code
        code = rank_walls_kick(motion, mpi, step, done)
        if code != 0:
            return done, largest[0], False, busy, code
        code = rank_coefficients_if_any(coefficients, mpi)
        if code != 0:
            return done, largest[0], False, busy, code
        drag_kick(*kicks)
        if count:
            below[0] = count
            if stop:
                return done + 1, largest[0], False, busy, 0
    return steps, largest[0], False, busy, 0


# one thread: the loops and their drag kernels without parallel regions (kernels/serial.py); the
# kernels' arrays are the particles', the drag's and the fluid's own fields, none a view of another
particle_drag_serial = serial_twin(particle_drag, distinct=True)
drag_kick_serial = serial_twin(drag_kick, distinct=True)
SERIAL_KERNELS = {
    "kick_drift": kick_drift_serial,
    "contacts": contacts_serial,
    "bin_particles": bin_particles_serial,
    "particle_drag": particle_drag_serial,
    "drag_kick": drag_kick_serial,
}
drag_steps_serial = serial_twin(drag_steps, **SERIAL_KERNELS)
rank_drag_steps_serial = serial_twin(rank_drag_steps, rank_drift=rank_drift_serial, **SERIAL_KERNELS)
