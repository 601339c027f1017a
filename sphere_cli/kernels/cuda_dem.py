"""The DEM step on a CUDA GPU (numba.cuda) (physics/device_steps.py). Every kernel strides over
its particles (or cells): thread t takes items t, t + T, t + 2T, ... of a launch of T threads, so
any launch gives the same results; a GPU launches one thread per item, Numba's simulator one
thread for all.

The same physics as the CPU kernels, from the same functions: the law of a contact is
laws.py contact_response, the periodic image neighbors.py minimum_image, the reduced mass
laws.py reduced (Numba compiles a CPU @njit function for the GPU where a kernel calls it).

Gather, no atomics in any sum: particle i's item computes every contact of i, in ascending
partner index, so each pair is computed by both its members, each as the pair's owner (the lower
index, as in kernels/contact.py) computes it; particle i's sum is then m g, minus the pairs
(j, i) with j < i, plus the pairs (i, j) with j > i, in ascending j: the order of the CPU sweep,
whatever the launch configuration. The springs are double-buffered: every thread reads the
springs of the last step (hist_in) and the owner writes the new one (hist_out), so the two
members read the same spring.

Neighbour search on the device: each particle's cell (cells of the CPU search,
physics/neighbors.py search_cells) takes a slot of its cell by an atomic count (which slot depends on
the scheduling, so each thread sorts its row after); a row holds every j != i within
r_i + r_j + skin (the CPU's test, symmetric in i and j), sorted ascending, with `mate[i, k]`,
the slot of i in the row of j; the spring of the pair (i, j), i < j, is hist[i, k] at the owner's
slot. Rows and cells have a capacity; a count beyond it is recorded and the caller grows the
arrays and builds again (nothing is dropped).

Arrays (N particles, F full-row slots, K slots per cell): pos ... (N,3) as on the CPU, fnbr
(N,F) int32, fcount (N,) int32, mate (N,F) int32, hist_in / hist_out (N,F,3) [m], cell_of (N,)
int64, cell_count (cells,) int32, cell_members (cells,K) int32; `worst` (1,) float64 and
`longest` (2,) int32: the reductions (a max, exact in any order).
"""

import functools
import math
import types

from numba import config, cuda, njit
from numba.core.dispatcher import Dispatcher

from . import contact_probe, exact_sum, motion, neighbors, walls
from .laws import D_N, D_T, HERTZ_MINDLIN, K_N, K_T, MU, MU_R, contact_response, reduced
from .neighbors import minimum_image, wrap_cell


def for_gpu(function):
    """A CPU @njit function, for the kernels: Numba compiles it for the GPU where a kernel calls
    it, inlined (one the CPU does not inline is taken again from its Python source with
    inline="always": numba-cuda would compile it as a device function of its own, whose target
    it asks of a GPU, so it could not be compiled where there is none). The simulator runs the
    kernels as Python, on arrays an @njit function cannot take, so there it is the Python
    function itself, calling the Python functions of the @njit functions it calls (the same
    operations)."""
    if config.ENABLE_CUDASIM:
        return _python(function)
    return _inlined(function)


def _calls(function) -> dict:
    """The @njit functions that `function` calls, by the global names it calls them by."""
    source = function.py_func
    return {
        name: value
        for name in source.__code__.co_names
        if isinstance(value := source.__globals__.get(name), Dispatcher)
    }


@functools.cache
def _inlined(function):
    """`function` inlined where it is called, with every @njit function it calls inlined too, down
    (one that the CPU compiles as a call of its own, for a shorter compile, taken again from its
    Python source with inline="always")."""
    called = _calls(function)
    calls = {name: _inlined(value) for name, value in called.items()}
    if function.targetoptions.get("inline") == "always" and all(calls[n] is called[n] for n in called):
        return function
    source = function.py_func
    scope = {**source.__globals__, **calls}
    code, name = source.__code__, source.__name__
    twin = types.FunctionType(code, scope, name, source.__defaults__, source.__closure__)
    return njit(inline="always")(twin)


def _python(function):
    """The Python function of an @njit function, with each @njit function it calls replaced by
    its own Python function, and so on down."""
    source = function.py_func
    calls = {name: _python(value) for name, value in _calls(function).items()}
    if not calls:
        return source
    scope = {**source.__globals__, **calls}
    code, name = source.__code__, source.__name__
    return types.FunctionType(code, scope, name, source.__defaults__, source.__closure__)


cell_number = for_gpu(neighbors.cell_number)
insert_ascending = for_gpu(neighbors.insert_ascending)
wall_normal = for_gpu(contact_probe.wall_normal)
unstable_reason = for_gpu(motion.unstable_reason)
wall_kick_drift = for_gpu(walls.wall_kick_drift)
exact_parts = for_gpu(exact_sum.exact_parts)
add_glued = for_gpu(walls.add_glued)
finish_wall_totals = for_gpu(walls.finish_wall_totals)
clear_sums = for_gpu(walls.clear_sums)
wall_areas = for_gpu(walls.wall_areas)
wall_kick = for_gpu(walls.wall_kick)
# module globals, so that Numba takes them as constants
BINS = exact_sum.BINS


@cuda.jit(device=True, inline=True)
def _half_kick(vel, angvel, force, torque, inv_mass, inv_inertia, half, i):
    """v += dt/2 F/m and w += dt/2 T/I for particle i (kernels/motion.py half_kick)."""
    for a in range(3):
        vel[i, a] += half * force[i, a] * inv_mass[i]
        angvel[i, a] += half * torque[i, a] * inv_inertia[i]


@cuda.jit
def kick_drift(
    pos, vel, angvel, force, torque, inv_mass, inv_inertia, lower, length, periodic, dt, vel_pred,
    angvel_pred, ref_pos, worst,
):  # fmt: skip
    """kernels/motion.py kick_drift for particle i; the largest squared displacement since the
    list was built into worst[0] (zeroed by the caller)."""
    for i in range(cuda.grid(1), pos.shape[0], cuda.gridsize(1)):
        half = 0.5 * dt
        _half_kick(vel, angvel, force, torque, inv_mass, inv_inertia, half, i)
        for a in range(3):
            vel_pred[i, a] = vel[i, a] + half * force[i, a] * inv_mass[i]
            angvel_pred[i, a] = angvel[i, a] + half * torque[i, a] * inv_inertia[i]
        moved2 = 0.0
        for a in range(3):
            y = pos[i, a] + dt * vel[i, a]
            if periodic[a]:
                if y >= lower[a] + length[a]:
                    y -= length[a]
                elif y < lower[a]:
                    y += length[a]
            pos[i, a] = y
            d = minimum_image(y - ref_pos[i, a], length[a], periodic[a])
            moved2 += d * d
        cuda.atomic.max(worst, 0, moved2)


@cuda.jit
def kick(vel, angvel, force, torque, inv_mass, inv_inertia, dt, worst):
    """kernels/motion.py kick for particle i; thread 0 zeroes worst[0] for the next step's
    kick-drift (which the kick precedes on the stream: no copy from the host a step)."""
    for i in range(cuda.grid(1), vel.shape[0], cuda.gridsize(1)):
        _half_kick(vel, angvel, force, torque, inv_mass, inv_inertia, 0.5 * dt, i)
        if i == 0:
            worst[0] = 0.0


@cuda.jit
def clear(counts):
    for c in range(cuda.grid(1), counts.shape[0], cuda.gridsize(1)):
        counts[c] = 0


@cuda.jit
def bin_particles(pos, lower, cell_size, ncell, cell_of, cell_count, cell_members, longest):
    """The cell of particle i (the CPU's, kernels/neighbors.py cell_number) and a slot in it;
    the fullest cell's count into longest[1]."""
    for i in range(cuda.grid(1), pos.shape[0], cuda.gridsize(1)):
        cell = cell_number(pos, i, lower, cell_size, ncell)
        cell_of[i] = cell
        slot = cuda.atomic.add(cell_count, cell, 1)
        if slot < cell_members.shape[1]:
            cell_members[cell, slot] = i
        cuda.atomic.max(longest, 1, slot + 1)


@cuda.jit(device=True, inline=True)
def _distinct(o, n, periodic):
    """Whether offset o (-1, 0, 1) reaches a cell that no other offset reaches (an axis of one
    cell, or of two periodic cells, has fewer neighbours than three)."""
    if n == 1:
        return o == 0
    if n == 2 and periodic:
        return o >= 0
    return True


@cuda.jit
def build_rows(
    pos, radius, length, periodic, ncell, cell_of, cell_count, cell_members, skin, fnbr, fcount, longest
):
    """Row i: every j != i within r_i + r_j + skin in the 27 cells around i's, ascending; its
    length into fcount[i] (beyond the capacity: counted, not stored) and longest[0]."""
    for i in range(cuda.grid(1), pos.shape[0], cuda.gridsize(1)):
        cap = fnbr.shape[1]
        c = cell_of[i]
        nz = ncell[2]
        cz = c % nz
        cy = (c // nz) % ncell[1]
        cx = c // (nz * ncell[1])
        xi = pos[i, 0]
        yi = pos[i, 1]
        zi = pos[i, 2]
        ri = radius[i]
        count = 0
        for ox in range(-1, 2):
            if not _distinct(ox, ncell[0], periodic[0]):
                continue
            gx = wrap_cell(cx + ox, ncell[0], periodic[0])
            if gx < 0:
                continue
            for oy in range(-1, 2):
                if not _distinct(oy, ncell[1], periodic[1]):
                    continue
                gy = wrap_cell(cy + oy, ncell[1], periodic[1])
                if gy < 0:
                    continue
                for oz in range(-1, 2):
                    if not _distinct(oz, nz, periodic[2]):
                        continue
                    gz = wrap_cell(cz + oz, nz, periodic[2])
                    if gz < 0:
                        continue
                    cell = (gx * ncell[1] + gy) * nz + gz
                    for s in range(min(cell_count[cell], cell_members.shape[1])):
                        j = cell_members[cell, s]
                        if j == i:
                            continue
                        dx = minimum_image(pos[j, 0] - xi, length[0], periodic[0])
                        dy = minimum_image(pos[j, 1] - yi, length[1], periodic[1])
                        dz = minimum_image(pos[j, 2] - zi, length[2], periodic[2])
                        reach = ri + radius[j] + skin
                        if dx * dx + dy * dy + dz * dz < reach * reach:
                            if count < cap:
                                insert_ascending(fnbr, i, count, j)
                            count += 1
        fcount[i] = count
        cuda.atomic.max(longest, 0, count)


@cuda.jit
def find_mates(fnbr, fcount, mate):
    """mate[i, k]: the slot of i in the row of j = fnbr[i, k] (the rows are symmetric and
    ascending: a binary search)."""
    for i in range(cuda.grid(1), fnbr.shape[0], cuda.gridsize(1)):
        for k in range(fcount[i]):
            j = fnbr[i, k]
            low = 0
            high = fcount[j]
            while low < high:
                mid = (low + high) // 2
                if fnbr[j, mid] < i:
                    low = mid + 1
                else:
                    high = mid
            mate[i, k] = low


@cuda.jit
def carry_springs(old_nbr, old_count, old_hist, fnbr, fcount, hist):
    """The springs of the owner's slots of the new rows (j > i): a pair listed before keeps its
    spring, a new one starts at zero (both rows ascending: one merge)."""
    for i in range(cuda.grid(1), fnbr.shape[0], cuda.gridsize(1)):
        p = 0
        old = old_count[i]
        for k in range(fcount[i]):
            j = fnbr[i, k]
            while p < old and old_nbr[i, p] < j:
                p += 1
            kept = j > i and p < old and old_nbr[i, p] == j
            for a in range(3):
                hist[i, k, a] = old_hist[i, p, a] if kept else 0.0


@cuda.jit(device=True, inline=True)
def _pair(
    o, j, pos, vel, angvel, vel_pred, angvel_pred, radius, inv_mass, inv_inertia, material, table, h0,
    h1, h2, law, rolling, length, periodic, spring_dt, step_dt,
):  # fmt: skip
    """The pair (o, j), o < j, as its owner o computes it (kernels/contact.py separation, gather
    and _pair_contact, with the same operations): (touching, contact_response's 12 values)."""
    ro = radius[o]
    rj = radius[j]
    d0 = minimum_image(pos[o, 0] - pos[j, 0], length[0], periodic[0])
    d1 = minimum_image(pos[o, 1] - pos[j, 1], length[1], periodic[1])
    d2 = minimum_image(pos[o, 2] - pos[j, 2], length[2], periodic[2])
    dist2 = d0 * d0 + d1 * d1 + d2 * d2
    reach = ro + rj
    if dist2 >= reach * reach:
        return False, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    dist = math.sqrt(dist2)
    inv = 1.0 / dist
    r_eff = 0.0
    if law == HERTZ_MINDLIN or rolling:
        r_eff = ro * rj / (ro + rj)
    i_eff = 0.0
    w0 = w1 = w2 = 0.0
    if rolling:
        i_eff = reduced(inv_inertia[o], inv_inertia[j])
        w0 = angvel[o, 0] - angvel[j, 0]
        w1 = angvel[o, 1] - angvel[j, 1]
        w2 = angvel[o, 2] - angvel[j, 2]
    a = 0
    b = 0
    if table.shape[0] > 1:
        a = material[o]
        b = material[j]
    row = (
        table[a, b, K_N], table[a, b, K_T], table[a, b, D_N], table[a, b, D_T], table[a, b, MU],
        table[a, b, MU_R],
    )  # fmt: skip
    e0, e1, e2, c0, c1, c2, m0, m1, m2, x0, x1, x2 = contact_response(
        (d0 * inv, d1 * inv, d2 * inv), reach - dist, math.sqrt(reduced(inv_mass[o], inv_mass[j])), r_eff,
        i_eff, row, law, rolling, spring_dt, step_dt,
        (vel[o, 0] - vel[j, 0], vel[o, 1] - vel[j, 1], vel[o, 2] - vel[j, 2]),
        (ro * angvel[o, 0] + rj * angvel[j, 0], ro * angvel[o, 1] + rj * angvel[j, 1],
         ro * angvel[o, 2] + rj * angvel[j, 2]),
        (vel_pred[o, 0] - vel_pred[j, 0], vel_pred[o, 1] - vel_pred[j, 1], vel_pred[o, 2] - vel_pred[j, 2]),
        (ro * angvel_pred[o, 0] + rj * angvel_pred[j, 0], ro * angvel_pred[o, 1] + rj * angvel_pred[j, 1],
         ro * angvel_pred[o, 2] + rj * angvel_pred[j, 2]),
        (h0, h1, h2),
        (w0, w1, w2),
    )  # fmt: skip
    return True, e0, e1, e2, c0, c1, c2, m0, m1, m2, x0, x1, x2


@cuda.jit
def pair_forces(
    pos, vel, angvel, vel_pred, angvel_pred, radius, inv_mass, inv_inertia, material, mass, body_acc,
    fnbr, fcount, mate, hist_in, hist_out, springs, table, law, rolling, length, periodic, spring_dt,
    step_dt, force, torque,
):  # fmt: skip
    """force = m g + the pair forces on i, torque = the pair torques (kernels/contact.py
    chunk_pair_forces, in its order); the owner's new springs into hist_out (springs: whether
    the pairs carry any; without, every spring read is zero and none is written)."""
    for i in range(cuda.grid(1), pos.shape[0], cuda.gridsize(1)):
        ri = radius[i]
        mi = mass[i]
        f0 = mi * body_acc[0]
        f1 = mi * body_acc[1]
        f2 = mi * body_acc[2]
        t0 = 0.0
        t1 = 0.0
        t2 = 0.0
        for k in range(fcount[i]):
            j = fnbr[i, k]
            # the pair as its owner computes it: (j, i) for j < i, whose force on j is negated here
            # (a - b and a + (-b) round alike), with the spring at the owner's slot
            owner, partner, s, sign = i, j, k, 1.0
            if j < i:
                owner, partner, s, sign = j, i, mate[i, k], -1.0
            h0 = h1 = h2 = 0.0
            if springs:
                h0 = hist_in[owner, s, 0]
                h1 = hist_in[owner, s, 1]
                h2 = hist_in[owner, s, 2]
            touching, e0, e1, e2, c0, c1, c2, m0, m1, m2, x0, x1, x2 = _pair(
                owner, partner, pos, vel, angvel, vel_pred, angvel_pred, radius, inv_mass, inv_inertia,
                material, table, h0, h1, h2, law, rolling, length, periodic, spring_dt, step_dt,
            )  # fmt: skip
            if touching:
                f0 += sign * e0
                f1 += sign * e1
                f2 += sign * e2
                t0 -= ri * c0  # n x F_t flips with n and F_t: the same term for both members
                t1 -= ri * c1
                t2 -= ri * c2
                if rolling:
                    t0 += sign * m0
                    t1 += sign * m1
                    t2 += sign * m2
            if springs and j > i:  # the owner writes the new spring (zero apart)
                hist_out[i, k, 0] = x0
                hist_out[i, k, 1] = x1
                hist_out[i, k, 2] = x2
        force[i, 0] = f0
        force[i, 1] = f1
        force[i, 2] = f2
        torque[i, 0] = t0
        torque[i, 1] = t1
        torque[i, 2] = t2


@cuda.jit(device=True, inline=True)
def _cleared(hist, i, w):
    """Whether spring hist[i, w] holds +0.0 in each component, the bits a cleared spring has (a
    -0.0 is written over, as on the CPU)."""
    for a in range(3):
        if hist[i, w, a] != 0.0 or math.copysign(1.0, hist[i, w, a]) < 0.0:
            return False
    return True


@cuda.jit
def wall_forces(
    pos, vel, angvel, vel_pred, angvel_pred, radius, mass, inertia, inv_mass, material, wall_axis,
    wall_sign, wall_coord, wall_vel, wall_vel_pred, wall_table, wall_hist, springs, law, rolling,
    spring_dt, step_dt, force, torque, record, pforce,
):  # fmt: skip
    """Add the forces of the plane walls on particle i, in wall order (kernels/walls.py
    wall_forces: the wall a body of infinite mass, radius and inertia, m* = m_i, R* = r_i,
    I* = I_i); its springs wall_hist[i] are its own, updated in place (springs: whether there are
    any); the force of each wall marked in record into pforce[i] (zero where it does not touch).
    A particle that does not move by forces touches no wall."""
    for i in range(cuda.grid(1), pos.shape[0], cuda.gridsize(1)):
        if inv_mass[i] == 0.0:
            continue
        ri = radius[i]
        ci = 0
        if wall_table.shape[1] > 1:
            ci = material[i]
        f0 = f1 = f2 = 0.0
        t0 = t1 = t2 = 0.0
        for w in range(wall_axis.shape[0]):
            touching, n0, n1, n2, delta = wall_normal(pos, radius, i, w, wall_axis, wall_sign, wall_coord)
            if not touching:
                if record[w]:
                    pforce[i, w, 0] = 0.0
                    pforce[i, w, 1] = 0.0
                    pforce[i, w, 2] = 0.0
                # the spring of a contact that has ended is gone; one that is zero already is not
                # written again (the rows of wall_hist are 144 bytes apart: six walls' stores from
                # every thread made this kernel the step's slowest, bound by the L1)
                if springs and not _cleared(wall_hist, i, w):
                    wall_hist[i, w, 0] = 0.0
                    wall_hist[i, w, 1] = 0.0
                    wall_hist[i, w, 2] = 0.0
                continue
            h0 = h1 = h2 = 0.0
            if springs:
                h0 = wall_hist[i, w, 0]
                h1 = wall_hist[i, w, 1]
                h2 = wall_hist[i, w, 2]
            i_eff = 0.0
            if rolling:
                i_eff = inertia[i]
            e0, e1, e2, c0, c1, c2, m0, m1, m2, x0, x1, x2 = contact_response(
                (n0, n1, n2), delta, math.sqrt(mass[i]), ri, i_eff,
                (
                    wall_table[w, ci, K_N], wall_table[w, ci, K_T], wall_table[w, ci, D_N],
                    wall_table[w, ci, D_T], wall_table[w, ci, MU], wall_table[w, ci, MU_R],
                ),
                law, rolling, spring_dt, step_dt,
                (vel[i, 0] - wall_vel[w, 0], vel[i, 1] - wall_vel[w, 1], vel[i, 2] - wall_vel[w, 2]),
                (ri * angvel[i, 0], ri * angvel[i, 1], ri * angvel[i, 2]),
                (
                    vel_pred[i, 0] - wall_vel_pred[w, 0], vel_pred[i, 1] - wall_vel_pred[w, 1],
                    vel_pred[i, 2] - wall_vel_pred[w, 2],
                ),
                (ri * angvel_pred[i, 0], ri * angvel_pred[i, 1], ri * angvel_pred[i, 2]),
                (h0, h1, h2),
                (angvel[i, 0], angvel[i, 1], angvel[i, 2]),
            )  # fmt: skip
            if springs:
                wall_hist[i, w, 0] = x0
                wall_hist[i, w, 1] = x1
                wall_hist[i, w, 2] = x2
            if record[w]:
                pforce[i, w, 0] = e0
                pforce[i, w, 1] = e1
                pforce[i, w, 2] = e2
            f0 += e0
            f1 += e1
            f2 += e2
            t0 -= ri * c0
            t1 -= ri * c1
            t2 -= ri * c2
            if rolling:
                t0 += m0
                t1 += m1
                t2 += m2
        force[i, 0] += f0
        force[i, 1] += f1
        force[i, 2] += f2
        torque[i, 0] += t0
        torque[i, 1] += t1
        torque[i, 2] += t2


@cuda.jit
def wall_motion_drift(
    wall_axis, wall_sign, mode, control, coord, vel, acc, vel_pred, shift, dt, attached, attached_wall, pvel
):  # fmt: skip
    """kernels/walls.py wall_kick_drift, on one thread: a few walls, and the glued particles in
    order."""
    if cuda.grid(1) == 0:
        wall_kick_drift(
            wall_axis, wall_sign, mode, control, coord, vel, acc, vel_pred, shift, dt, attached,
            attached_wall, pvel,
        )  # fmt: skip


@cuda.jit
def push_sums(pforce, rows, record, sums):
    """Each particle's push on the walls marked in record (the first `rows` of pforce) into
    their exact sums (kernels/walls.py add_pushes), by integer atomics: exact, so the same
    whatever the order of the threads."""
    for i in range(cuda.grid(1), rows, cuda.gridsize(1)):
        for w in range(record.shape[0]):
            if record[w]:
                for b in range(3):
                    value = -pforce[i, w, b]
                    if value == 0.0:
                        continue
                    if not math.isfinite(value):
                        cuda.atomic.add(sums, (w, b, BINS), 1)
                        continue
                    k, low, middle, high = exact_parts(value)  # as kernels/exact_sum.py add_exact adds them
                    cuda.atomic.add(sums, (w, b, k), low)
                    cuda.atomic.add(sums, (w, b, k + 1), middle)
                    cuda.atomic.add(sums, (w, b, k + 2), high)


@cuda.jit
def wall_motion_kick(
    sums, record, attached, attached_wall, pforce_total, mass, body_acc, fluid_force, wall_force, wall_axis,
    wall_sign, coord, lower, upper, area, mode, control, vel, acc, time, dt,
):  # fmt: skip
    """The second half kick of the walls on one thread (physics/walls.py WallMotion.kick): the
    glued particles into the sums, the forces on the walls (finish_wall_totals), their areas,
    the kick at `time`, and the sums cleared for the next step's push_sums."""
    if cuda.grid(1) == 0:
        add_glued(attached, attached_wall, pforce_total, mass, body_acc, record, sums)
        finish_wall_totals(sums, record, fluid_force, wall_force)
        clear_sums(sums)
        wall_areas(wall_axis, wall_sign, coord, lower, upper, area)
        wall_kick(wall_axis, wall_sign, mode, control, wall_force, area, vel, acc, time, dt)


@cuda.jit
def find_unstable(pos, vel, angvel, radius, lower, upper, periodic, dt, first):
    """The lowest index of a particle that has gone bad (kernels/motion.py unstable_reason) into
    first[0] (set to N by the caller): a min, the same whatever the order of the threads."""
    for i in range(cuda.grid(1), pos.shape[0], cuda.gridsize(1)):
        if unstable_reason(pos, vel, angvel, radius, lower, upper, periodic, dt, i):
            cuda.atomic.min(first, 0, i)
