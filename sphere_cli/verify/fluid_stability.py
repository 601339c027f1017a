"""Stability suite, the fluids (verification group E): stiff and extreme input to each fluid
model, each accurate within a stated tolerance or refused naming the limit, never a silent
blow-up or a NaN reported as something else. Registered into stability.py's suite.
"""

from __future__ import annotations

import math
import textwrap

import numpy as np

from ..config.load import parse_case
from ..errors import CaseError, SphereError
from ..kernels.fluid.drag import GIDASPOW, drag_rate
from ..scene.builder import build_scene
from ..simulation import advance
from .darcy_reference import COMPRESSIBILITY, POROSITY, VISCOSITY, column, terzaghi_pressure
from .fluid_cases import bed_column
from .stability import StabilityCase, _first_line, _register

GLYCERIN, MU_GLYCERIN, GLASS, G = 1260.0, 1.41, 2500.0, 9.81


def _record(action, detail, checks, theory=None, limit=None, exit_code=0) -> dict:
    return {
        "action": action,
        "exit_code": exit_code,
        "theory": theory,
        "theory_dt_s": limit,
        "largest_stable_ratio": None,
        "detail": detail,
        "checks": checks,
    }


def _refusal(error, named: tuple[str, ...], accepted: str, theory: str, limit: float) -> dict:
    """The record of a case that must be refused before the run: a CaseError (exit 65) whose
    message holds every text in `named` (the key, the limit); `accepted` says what happened
    when it was not refused."""
    message = str(error) if error is not None else ""
    refused = isinstance(error, CaseError)
    return _record(
        "refused" if refused else "ran",
        _first_line(message) or accepted,
        [
            {"check": "refused with a CaseError (exit 65)", "passed": refused, "detail": ""},
            {
                "check": "the message names " + " and ".join(named),
                "passed": all(text in message for text in named),
                "detail": _first_line(message),
            },
        ],
        theory=theory,
        limit=limit,
        exit_code=getattr(error, "exit_code", 0),
    )


def _build(text: str):
    """(error, scene) of a case text: a SphereError raised while it is read or built, or the scene."""
    try:
        return None, build_scene(parse_case(textwrap.dedent(text)))
    except SphereError as exc:
        return exc, None


# ------------------------------------------------------------------ drag far below dt, Navier-Stokes

FINE = """
[simulation]
duration = 1.0
dt = 1.6e-7
[domain]
upper = [4e-4, 4e-4, 8e-4]
periodic = [true, true, false]
gravity = [0.0, 0.0, -9.81]
[particles]
count = 1
density = 2500.0
radius = { distribution = "fixed", value = 5e-6 }
[particles.placement]
method = "lattice"
region_lower = [1.8e-4, 1.8e-4, 4e-4]
region_upper = [2.2e-4, 2.2e-4, 4.4e-4]
[contact]
normal_stiffness = 1.0
[fluid]
model = "navier-stokes"
density = 1260.0
viscosity = 1.41
grid = { cells = [10, 10, 20] }
top = { type = "no-flow" }
"""


def fine_sphere_navier_stokes(quick: bool) -> dict:
    """A 10 um glass sphere in glycerol (tau_p = rho_p d^2/(18 mu) = 10 ns) at dt = 0.16 us, just
    under the fluid's viscous limit and 16 tau_p: the exact relaxation of the drag keeps it stable,
    and it settles at the terminal velocity of the drag law at its cell's porosity within 5 %
    (the box of 40 d holds its own hindrance)."""
    error, scene = _build(FINE)
    if error is not None:
        return _record("refused", _first_line(str(error)), [], exit_code=error.exit_code)
    p = scene.state.particles
    d = 2.0 * float(p.radius[0])
    tau = GLASS * d * d / (18.0 * MU_GLYCERIN)
    dt = scene.state.clock.dt
    advance(scene, 200 if quick else 1000)
    phi = float(scene.state.fluid.porosity.reshape(-1)[scene.fluid.drag.cell_of[0]])
    volume = math.pi / 6.0 * d**3
    weight = (GLASS - GLYCERIN) * G * volume
    terminal = weight / (3.0 * math.pi * MU_GLYCERIN * d)
    for _ in range(50):  # the law's own terminal velocity, by fixed point
        terminal = weight / (volume * drag_rate(GIDASPOW, phi, d, terminal, GLYCERIN, MU_GLYCERIN, 0.1))
    v = -float(p.vel[0, 2])
    finite = bool(np.isfinite(p.vel).all() and np.isfinite(scene.state.fluid.v_face).all())
    return _record(
        "ran",
        f"dt = {dt:.3g} s = {dt / tau:.0f} tau_p; settling at {v:.4g} m/s, the law's terminal "
        f"velocity {terminal:.4g} m/s at porosity {phi:.4f}",
        [
            {"check": "dt far above tau_p (> 10)", "passed": dt > 10 * tau, "detail": f"{dt / tau:.0f}"},
            {"check": "finite", "passed": finite, "detail": ""},
            {
                "check": "terminal velocity within 5 %",
                "passed": finite and abs(v / terminal - 1.0) < 0.05,
                "detail": f"{v / terminal - 1.0:+.2%}",
            },
        ],
        theory="exact relaxation of the drag over each half step: stable for any dt/tau_p",
    )


_register(
    StabilityCase(
        "stability-fluid-fine-sphere-navier-stokes",
        "a 10 um sphere in glycerol, its drag relaxation time 16x below dt (Navier-Stokes)",
        "ran",
        fine_sphere_navier_stokes,
    )
)


# ------------------------------------------------------------------ drag far below dt, 1D VANS

FINE_SEDIMENT = """
[simulation]
duration = 0.001
dt = {dt}
[domain]
upper = [0.001, 0.001, 0.002]
periodic = [true, true, false]
gravity = [0.5, 0.0, -9.8]
[particles]
count = 8
density = 2650.0
radius = {{ distribution = "fixed", value = 5e-5 }}
placement = {{ method = "lattice" }}
[contact]
normal_stiffness = 1.0e-3
[fluid]
model = "vans1d"
surface = 0.002
cells = 20
"""


def fine_sediment_vans1d(quick: bool) -> dict:
    """Fine sediment (0.1 mm quartz in water, drag relaxation m/K about 0.1 ms with the hindrance
    of a packed bed) under the 1D VANS fluid, whose drag on the particles is explicit: a dt 10
    times that limit must be refused before the run, naming simulation.dt and the limit (dt =
    "auto" stays below it; the contacts are soft so that the drag sets it)."""
    _, auto = _build(FINE_SEDIMENT.format(dt='"auto"'))
    limit = float(auto.dt_limit)
    error, _ = _build(FINE_SEDIMENT.format(dt=repr(10.0 * limit)))
    return _refusal(
        error,
        ("simulation.dt", f"{limit:.4g}", "drag"),
        "accepted dt = 10 x the drag relaxation limit",
        auto.dt_limit_reason,
        limit,
    )


_register(
    StabilityCase(
        "stability-fluid-fine-sediment-vans1d",
        "fine sediment under the 1D VANS fluid at 10x its explicit drag limit",
        "refused",
        fine_sediment_vans1d,
    )
)


# ------------------------------------------------------------------ Darcy at 100x its explicit limit


def darcy_far_above_explicit_limit(quick: bool) -> dict:
    """Terzaghi consolidation on 100 cells at dt = 100 x the explicit diffusion limit h^2/(2D):
    backward Euler is L-stable (no ringing), and at T = 0.1 (20 steps) the pressure is within
    1 % of p0 of the series solution."""
    height, p0, n = 1.0, 1.0e4, 100
    model = column(
        n, height, {"permeability": {"model": "constant", "value": 1e-12}, "initial_pressure": p0,
                    "bottom": {"type": "no-flow"}},
    )  # fmt: skip
    diffusivity = 1e-12 / (COMPRESSIBILITY * POROSITY * VISCOSITY)
    dt = 100.0 * model.explicit_limit()
    steps = round(0.1 * height**2 / diffusivity / dt)
    for step in range(1, steps + 1):
        model.advance(dt, step * dt)
    p = model.state.pressure[0, 0]
    error = float(np.max(np.abs(p - terzaghi_pressure(height - model.grid.centres(2), 0.1, p0, height))) / p0)
    bounded = bool(np.all((p >= -1e-9 * p0) & (p <= p0 * (1 + 1e-9))))
    return _record(
        "ran",
        f"{steps} steps of 100 x the explicit limit: max |p - exact| = {error:.2e} p0",
        [
            {"check": "within 1 % of p0", "passed": error < 0.01, "detail": f"{error:.2e}"},
            {"check": "no overshoot (0 <= p <= p0)", "passed": bounded, "detail": ""},
        ],
        theory="backward Euler in time: unconditionally stable",
        limit=model.explicit_limit(),
    )


_register(
    StabilityCase(
        "stability-fluid-darcy-100x-explicit-limit",
        "Darcy diffusion at 100x its explicit limit (Terzaghi)",
        "ran",
        darcy_far_above_explicit_limit,
    )
)


# ------------------------------------------------------------------ the coupling beyond its limit

COUPLED = """
[simulation]
duration = 0.01
[domain]
upper = [0.004, 0.004, 0.008]
periodic = [true, true, false]
[particles]
count = 1
density = 2500.0
radius = {{ distribution = "fixed", value = 5e-4 }}
placement = {{ method = "lattice", region_lower = [0.0, 0.0, 0.003] }}
[contact]
normal_stiffness = 100.0
[fluid]
model = "navier-stokes"
grid = {{ cells = [2, 2, 4] }}
coupling = {{ interval = {interval} }}
"""


def coupling_beyond_its_limit(quick: bool) -> dict:
    """A Navier-Stokes coupling interval twice the fluid step's viscous limit must be refused
    before the run, naming fluid.coupling.interval and the limit."""
    _, ok = _build(COUPLED.format(interval=1e-4))
    limit = float(ok.fluid.fluid_step_limit()[0])
    error, _ = _build(COUPLED.format(interval=repr(2.0 * limit)))
    return _refusal(
        error,
        ("fluid.coupling.interval", f"{limit:.4g}"),
        "accepted an interval of twice the limit",
        "the fluid step's viscous limit dx^2/(8 nu)",
        limit,
    )


_register(
    StabilityCase(
        "stability-fluid-coupling-beyond-its-limit",
        "a Navier-Stokes coupling interval at twice the fluid step's limit",
        "refused",
        coupling_beyond_its_limit,
    )
)


# ------------------------------------------------------------------ porosity at the drag-law switch


def porosity_at_the_drag_switch(quick: bool) -> dict:
    """A fixed bed of porosity exactly 0.8, where Gidaspow's law switches from Wen-Yu to Ergun
    (it takes Ergun at <= 0.8; the two differ by 1.153 there), grains of 1 mm, 5 Pa across the
    column (fluid_cases.bed_column): the run is stable and the pressure gradient across the bed
    is Ergun's at the flow within 1 %."""
    try:
        scene, _, superficial, gradient, ergun = bed_column(40, 5.0, 0.8, 1e-3, 20)
    except SphereError as error:
        return _record("refused", _first_line(str(error)), [], exit_code=error.exit_code)
    fs = scene.state.fluid
    finite = bool(np.isfinite(fs.v_face).all() and np.isfinite(fs.p).all())
    return _record(
        "ran",
        f"U = {superficial:.4g} m/s, gradient {gradient:.5g} Pa/m against Ergun's {ergun:.5g}",
        [
            {"check": "finite", "passed": finite, "detail": ""},
            {
                "check": "Ergun's gradient within 1 % (the law's branch at 0.8)",
                "passed": finite and abs(gradient / ergun - 1.0) < 0.01,
                "detail": f"{gradient / ergun - 1.0:+.3%}",
            },
        ],
        theory="Gidaspow: Ergun at porosity <= 0.8, Wen-Yu above",
    )


_register(
    StabilityCase(
        "stability-fluid-porosity-at-the-drag-switch",
        "a fixed bed at porosity exactly 0.8, the switch of Gidaspow's drag law",
        "ran",
        porosity_at_the_drag_switch,
    )
)
