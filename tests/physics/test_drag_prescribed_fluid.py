"""Particles in a prescribed fluid state (one-way coupling): the drag module of physics/fluid/drag.py
driven by the real DEM loop (velocity Verlet with its second half kick replaced), and its
momentum exchange with the fluid (verification group D and E).
"""

from __future__ import annotations

import math

import numba
import numpy as np
import pytest
from dem_physics_cases import make_scene

from sphere_cli.verify.coupled_cases import (
    GLYCERIN,
    MU,
    STEEL,
    G,
    advance_in_held_fluid,
    held_fluid,
    held_fluid_drag,
    settling_reference,
)


def single_sphere(tmp_path, d, density, dt, vel=(0.0, 0.0, 0.0)):
    box = max(20.0 * d, 5e-3)  # (the case checks compare the box with the default radius, 1 mm)
    return make_scene(
        tmp_path,
        [[box / 2, box / 2, box / 2]],
        d / 2,
        [vel],
        density=density,
        gravity=(0.0, 0.0, -G),
        upper=(box, box, box),
        periodic=(True, True, True),
        dt=dt,
    )


def test_stokes_settling_one_way(tmp_path):
    """D: steel d = 2 mm in glycerol at rest (isolated, phi = 1, hydrostatic pressure gradient
    giving the buoyancy): v(t) follows the Schiller-Naumann equation of motion (whose Stokes
    limit is v_t (1 - exp(-t/tau_p)), tau_p = rho_p d^2/(18 mu) = 1.229 ms) within 1 % of v_t at
    every sampled time, and reaches v_t = 0.010017 m/s within 1 % (validation D). dt = tau_p/50.
    Measured: largest deviation 1.3e-5 of v_t (the drag is integrated exactly at frozen K; what is
    left is K lagging half a step behind v)."""
    d = 2.0e-3
    tau = STEEL * d * d / (18.0 * MU)
    dt = tau / 50.0
    scene = single_sphere(tmp_path, d, STEEL, dt)
    fs = held_fluid((2, 2, 2), (10 * d,) * 3, grad_p=(0.0, 0.0, -GLYCERIN * G))
    drag = held_fluid_drag(scene, fs)
    times, speeds = [], []
    for _ in range(20):
        advance_in_held_fluid(scene, drag, fs, 25)
        times.append(scene.state.clock.time)
        speeds.append(-scene.state.particles.vel[0, 2])
    reference = settling_reference(d, STEEL, GLYCERIN, MU, times)
    v_t = 0.010017
    assert np.max(np.abs(np.array(speeds) - reference)) < 0.01 * v_t
    assert speeds[-1] == pytest.approx(v_t, rel=0.01)  # t = 10 tau_p: within 5e-5 of terminal
    stokes = (STEEL - GLYCERIN) * G * d * d / (18 * MU) * (1 - np.exp(-np.array(times) / tau))
    assert np.max(np.abs(np.array(speeds) - stokes)) < 0.015 * v_t  # Stokes vs SN: 0.94 % at v_t
    assert np.all(scene.state.particles.vel[0, :2] == 0.0)


@pytest.mark.parametrize("law", ["gidaspow", "di-felice"])
def test_drag_relaxation_far_below_dt_is_stable_and_exact(tmp_path, law):
    """E: 10 um glass (2500 kg/m^3) in glycerol: tau_p = rho_p d^2/(18 mu) ~ 1e-8 s; with
    dt = 100 tau_p explicit drag would diverge (factor 1 - dt/tau_p = -99 a step). Here the
    particle, started at 1 m/s across a fluid flowing at 0.01 m/s along x, is at the terminal
    velocity (u_x, and -v_t vertically, v_t from the law's own K at that speed) after one step
    and stays there: no overshoot, no oscillation, to 1e-9 relative. The fluid then carries the
    particle's inertia in its implicit drag coefficient."""
    d = 10e-6
    tau = 2500.0 * d * d / (18.0 * MU)
    scene = single_sphere(tmp_path, d, 2500.0, 100.0 * tau, vel=(0.0, 1.0, 0.0))
    fs = held_fluid((2, 2, 2), (2.5e-3,) * 3, v=(0.01, 0.0, 0.0), grad_p=(0.0, 0.0, -GLYCERIN * G))
    drag = held_fluid_drag(scene, fs, law=law)
    p = scene.state.particles
    history = []
    for _ in range(20):
        advance_in_held_fluid(scene, drag, fs, 1)
        history.append(p.vel[0].copy())
    history = np.array(history)
    k = drag.coef[0]
    v_t = (2500.0 - GLYCERIN) * G * math.pi / 6 * d**3 / k
    expected = np.array([0.01, 0.0, -v_t])
    np.testing.assert_allclose(history[1:], np.tile(expected, (19, 1)), rtol=1e-9, atol=1e-9 * 0.01)
    assert np.all(np.isfinite(history))
    # the fluid's implicit coefficient over a fluid step of 10 dt: the particle follows the fluid
    # within it, so the fluid carries its inertia m/dt_f (to e^-1000), not K (1000 times more)
    fluid_dt = 10 * scene.state.clock.dt
    drag.fluid_forcing(scene.state, fs, fluid_dt)
    carried = fs.k_drag.sum() * float(np.prod(fs.grid.spacing)) * fluid_dt
    assert carried == pytest.approx(p.mass[0], rel=1e-12)


def _random_bed(tmp_path, n=120, seed=3):
    rng = np.random.default_rng(seed)
    box = np.array([5e-3, 4e-3, 6e-3])
    r = rng.uniform(0.8e-4, 1.2e-4, n)
    pos = rng.uniform(0.0, 1.0, (n, 3)) * box
    vel = rng.normal(0.0, 0.01, (n, 3))
    scene = make_scene(
        tmp_path,
        pos,
        r,
        vel,
        density=2500.0,
        upper=tuple(box),
        periodic=(True, True, True),
        gravity=(0.0, 0.0, -G),
        dt=1e-6,
        stability="contact",
        overlap_tolerance=0.5,
    )
    fs = held_fluid((5, 4, 6), (1e-3, 1e-3, 1e-3))
    fs.v[...] = rng.normal(0.0, 0.02, fs.v.shape)
    fs.porosity[...] = rng.uniform(0.35, 1.0, fs.porosity.shape)
    fs.porosity.flat[0] = 0.05  # below the floor: clamped, with a warning
    fs.grad_p[...] = rng.normal(0.0, 1e4, fs.grad_p.shape)
    return scene, fs


@pytest.mark.parametrize("formulation_b", [False, True])
@pytest.mark.parametrize("law", ["gidaspow", "di-felice"])
def test_fluid_receives_exactly_what_the_particles_received(tmp_path, law, formulation_b):
    """Newton's third law over a fluid interval of 3 DEM steps: what fluid_forcing settles for
    the interval, summed over the cells times cell volume and interval, is the momentum the drag
    gave the particles, m (v_3 - v_0) less the impulse of every other force over the three steps
    (h (F_0 + 2 F_1 + 2 F_2 + F_3), h = dt/2, velocity Verlet), plus in formulation B the
    pressure-gradient force (A carries its reaction in -phi grad p). The settled part of f_i is
    f_i less the new prediction plus what the last fluid step took (the old prediction and its
    implicit part f_exchange - f_i, here random). To round-off: 1e-12 of the particles' momentum
    (sums over 120 particles in another order). And the prediction is the exact relaxation's
    mean drag at the fluid velocity now (kernels/fluid/drag.py)."""
    scene, fs = _random_bed(tmp_path)
    with pytest.warns(RuntimeWarning, match="porosity_floor"):
        drag = held_fluid_drag(scene, fs, 1000.0, 1e-3, formulation_b, law=law)
    p = scene.state.particles
    dt = scene.state.clock.dt
    volume = math.pi / 6 * (2 * p.radius) ** 3
    cell_volume = 1e-9
    scale = 1e-12 * np.abs(p.mass[:, None] * p.vel).sum()
    implicit = np.zeros(fs.f_i.shape)
    for interval in range(2):
        v0 = p.vel.copy()
        other = [drag.f_other.copy()]
        for _ in range(3):
            advance_in_held_fluid(scene, drag, fs, 1)
            other.append(drag.f_other.copy())
        fs.f_exchange[...] = fs.f_i + implicit
        took = implicit + drag.predicted.reshape(fs.f_i.shape)
        drag.fluid_forcing(scene.state, fs, 3 * dt)
        others = 0.5 * dt * (other[0] + 2 * other[1] + 2 * other[2] + other[3])
        gained = (p.mass[:, None] * (p.vel - v0) - others).sum(axis=0)
        if formulation_b:
            gained -= 3 * dt * (volume[:, None] * fs.grad_p.reshape(-1, 3)[drag.cell_of]).sum(axis=0)
        settled = fs.f_i - drag.predicted.reshape(fs.f_i.shape) + took
        exchanged = settled.reshape(-1, 3).sum(axis=0) * cell_volume * 3 * dt
        assert np.abs(gained).max() > 1e6 * scale  # the drag did act
        np.testing.assert_allclose(exchanged, gained, rtol=0, atol=scale)
        assert not drag.impulse.any()  # handed over
        assert fs.k_drag.sum() > 0.0
        implicit = np.random.default_rng(interval).normal(0.0, 1.0, fs.f_i.shape)
    # the prediction: sum over a cell's particles of phi1 K (u - v) + (phi1 - 1) F_o
    from sphere_cli.kernels.fluid.drag import phi1

    g = np.array([phi1(x) for x in drag.coef * p.inv_mass * 3 * dt])
    expected = g[:, None] * drag.coef[:, None] * (fs.v.reshape(-1, 3)[drag.cell_of] - p.vel)
    expected += (g - 1.0)[:, None] * drag.f_other
    per_cell = np.zeros((fs.k_drag.size, 3))
    np.add.at(per_cell, drag.cell_of, expected / cell_volume)
    np.testing.assert_allclose(drag.predicted, per_cell, rtol=1e-12, atol=1e-12 * np.abs(per_cell).max())
    # the particles felt the drag the kick computed: force = other + drag
    np.testing.assert_array_equal(p.force, drag.f_other + drag.f_drag)
    total = drag.fluid_force(scene.state, fs)
    pressure = -(volume[:, None] * fs.grad_p.reshape(-1, 3)[drag.cell_of]).sum(axis=0)
    np.testing.assert_allclose(
        total, drag.f_drag.sum(axis=0) + pressure, rtol=1e-14, atol=1e-14 * np.abs(pressure).max()
    )


def test_exchange_and_kick_do_not_depend_on_the_thread_count(tmp_path):
    """Gather per cell in particle order: f_i, k_drag and the particle state are bitwise equal
    with 1 and 2 Numba threads."""
    results = []
    for threads in (1, 2):
        numba.set_num_threads(threads)
        (tmp_path / str(threads)).mkdir()
        scene, fs = _random_bed(tmp_path / str(threads))
        with pytest.warns(RuntimeWarning):
            drag = held_fluid_drag(scene, fs, 1000.0, 1e-3, True)
        advance_in_held_fluid(scene, drag, fs, 3)
        drag.fluid_forcing(scene.state, fs, 3e-6)
        p = scene.state.particles
        results.append((fs.f_i.copy(), fs.k_drag.copy(), p.vel.copy(), p.force.copy()))
    for a, b in zip(*results, strict=True):
        np.testing.assert_array_equal(a, b)
