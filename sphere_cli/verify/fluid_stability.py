"""Stability suite, the fluids (verification group E): stiff and extreme input to each fluid
model, each accurate within a stated tolerance or refused naming the limit, never a silent
blow-up or a NaN reported as something else. Registered into stability.py's suite.
"""

from __future__ import annotations

import math
import tempfile
import textwrap
from pathlib import Path

import numpy as np

from ..config.load import parse_case
from ..errors import CaseError, SphereError
from ..scene.builder import build_scene
from ..simulation import advance
from .darcy_reference import COMPRESSIBILITY, POROSITY, VISCOSITY, column, terzaghi_pressure
from .fluid_cases import BED_COLUMN, bed_column
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


def _terminal_check(speed: float, terminal: float, finite: bool) -> dict:
    """The check of a settling case: its speed within 5 % of the drag law's terminal velocity
    at its cell's porosity (the box's own hindrance and the coupling's wake model stay below)."""
    return {
        "check": "terminal velocity within 5 %",
        "passed": finite and abs(speed / terminal - 1.0) < 0.05,
        "detail": f"{speed / terminal - 1.0:+.2%}",
    }


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
    terminal = scene.fluid.drag.settling_speed(d, GLASS - GLYCERIN, G, phi)  # the law's own
    v = -float(p.vel[0, 2])
    finite = bool(np.isfinite(p.vel).all() and np.isfinite(scene.state.fluid.v_face).all())
    return _record(
        "ran",
        f"dt = {dt:.3g} s = {dt / tau:.0f} tau_p; settling at {v:.4g} m/s, the law's terminal "
        f"velocity {terminal:.4g} m/s at porosity {phi:.4f}",
        [
            {"check": "dt far above tau_p (> 10)", "passed": dt > 10 * tau, "detail": f"{dt / tau:.0f}"},
            {"check": "finite", "passed": finite, "detail": ""},
            _terminal_check(v, terminal, finite),
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


# ------------------------------------------------------------------ the Darcy coupling far below dt

FINE_DARCY = (
    FINE.split("[fluid]")[0]
    + """[fluid]
model = "darcy"
viscosity = 1.41
grid = { cells = [10, 10, 20] }
"""
)


def fine_sphere_darcy(quick: bool) -> dict:
    """The same 10 um glass sphere in glycerol under the Darcy fluid, whose coupling is explicit:
    its relaxation time rho_s k (1 - phi)/mu (Kozeny-Carman k at the densest packing, k_c =
    d^2/180) is picoseconds, so the case's dt (0.16 us) must be refused before the run, naming
    simulation.dt, the limit and the coupling (dt = "auto" stays below it)."""
    _, auto = _build(FINE_DARCY.replace("dt = 1.6e-7", 'dt = "auto"'))
    limit = float(auto.dt_limit)
    error, _ = _build(FINE_DARCY)
    return _refusal(
        error,
        ("simulation.dt", f"{limit:.4g}", "explicit Darcy coupling"),
        "accepted dt = 0.16 us, far above the coupling's limit",
        auto.dt_limit_reason,
        limit,
    )


_register(
    StabilityCase(
        "stability-fluid-fine-sphere-darcy",
        "a 10 um sphere in glycerol under the Darcy fluid, dt far above its coupling limit",
        "refused",
        fine_sphere_darcy,
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
    """A Navier-Stokes coupling interval twice the fluid step's limit (here the settling
    particle's crossing of half a cell, below the viscous limit) must be refused before the
    run, naming fluid.coupling.interval and the limit."""
    _, ok = _build(COUPLED.format(interval=1e-4))
    limit, reason = ok.fluid.fluid_step_limit()
    error, _ = _build(COUPLED.format(interval=repr(2.0 * limit)))
    return _refusal(
        error,
        ("fluid.coupling.interval", f"{limit:.4g}"),
        "accepted an interval of twice the limit",
        reason,
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


# ------------------------------------------------------------------ particle Reynolds number > 1000

HIGH_REYNOLDS = """
[simulation]
duration = 1.0
[domain]
upper = [0.08, 0.08, 0.64]
periodic = [true, true, false]
gravity = [0.0, 0.0, -9.81]
[particles]
density = 7800.0
placement = { method = "file", path = "sphere.csv" }
[contact]
normal_stiffness = 1000.0
[fluid]
model = "navier-stokes"
grid = { cells = [4, 4, 32] }
top = { type = "no-flow" }
"""


def high_reynolds_navier_stokes(quick: bool) -> dict:
    """A 5 mm steel sphere falling through water (Re_p = rho d v/mu about 5000, the drag's
    Newton branch C_d = 0.44) at dt = "auto", which keeps it within half a cell a fluid step:
    stable (the run's own stability check passes: fluid Courant number, the particle's crossing
    of cells), and at the law's terminal velocity at its cell's porosity within 5 % after 0.4 s
    (it reaches it within 0.3 s), released 2 cells below the closed top."""
    with tempfile.TemporaryDirectory(prefix="sphere-stability-") as tmp:
        (Path(tmp) / "sphere.csv").write_text("x,y,z,r\n0.0405,0.04,0.6,0.0025\n")
        try:
            scene = build_scene(parse_case(textwrap.dedent(HIGH_REYNOLDS), Path(tmp) / "case.toml"))
        except SphereError as error:
            return _record("refused", _first_line(str(error)), [], exit_code=error.exit_code)
    p, dt = scene.state.particles, scene.state.clock.dt
    advance(scene, round(0.4 / dt))
    unstable = scene.fluid.first_unstable(scene.state)
    d = 2.0 * float(p.radius[0])
    phi = float(scene.state.fluid.porosity.reshape(-1)[scene.fluid.drag.cell_of[0]])
    terminal = scene.fluid.drag.settling_speed(d, 7800.0 - 1000.0, G, phi)
    v = -float(p.vel[0, 2])
    reynolds = 1000.0 * d * v / 1e-3
    finite = bool(np.isfinite(p.vel).all() and np.isfinite(scene.state.fluid.v_face).all())
    return _record(
        "ran",
        f"dt = {dt:.3g} s ({scene.dt_limit_reason}); Re_p = {reynolds:.0f}, falling at {v:.4g} m/s, "
        f"the law's terminal velocity {terminal:.4g} m/s at porosity {phi:.4f}",
        [
            {"check": "Re_p above 1000", "passed": reynolds > 1000.0, "detail": f"{reynolds:.0f}"},
            {"check": "finite, and the run's stability check passes", "passed": finite and unstable is None,
             "detail": unstable or ""},
            _terminal_check(v, terminal, finite),
        ],
        theory="a settling particle crosses at most half a cell a fluid step (dt = auto)",
        limit=float(scene.dt_limit),
    )  # fmt: skip


_register(
    StabilityCase(
        "stability-fluid-high-reynolds-navier-stokes",
        "a 5 mm steel sphere falling through water at a particle Reynolds number of 5000",
        "ran",
        high_reynolds_navier_stokes,
    )
)


# ------------------------------------------------------------------ pressure pulses


def pulsed(period: float) -> str:
    """The bed column of fluid_cases.py (40 cells of 1 mm, dt = "auto" 0.1125 s) driven from below
    by 10 Pa modulated by 5 Pa with this period [s]."""
    bottom = f'{{ type = "pressure", pressure = 10.0, amplitude = 5.0, period = {period!r} }}'
    return BED_COLUMN.format(cells=40, bottom=bottom, porosity=0.4, diameter=6e-4)


def pulse_faster_than_the_fluid_step(quick: bool) -> dict:
    """A boundary pressure modulated with a period of 1.5 fluid steps: sampled at the steps it
    would alias into a slower modulation, a plausible wrong answer; it must be refused before
    the run, naming fluid.bottom.period and the least period."""
    _, ok = _build(pulsed(100.0))
    step = float(ok.state.clock.dt)
    error, _ = _build(pulsed(1.5 * step))
    return _refusal(
        error,
        ("fluid.bottom.period", "alias", f"{2.0 * step:.4g}"),
        "accepted a modulation of 1.5 fluid steps a period",
        "two fluid steps a period at least (sampling)",
        step,
    )


_register(
    StabilityCase(
        "stability-fluid-pulse-faster-than-the-fluid-step",
        "a boundary pressure modulated faster than the fluid step samples it",
        "refused",
        pulse_faster_than_the_fluid_step,
    )
)


def darcy_pulse_faster_than_diffusion(quick: bool) -> dict:
    """Top pressure A sin(omega t) over a 1 m layer on 50 cells whose period is 1e-3 of the
    diffusion time of one cell (skin depth 0.018 cells), 40 steps a period, from p = 0. The
    grid cannot resolve the skin: what it must do is stay bounded (|p| <= A, no ringing) and
    give the periodic state of its own scheme, the complex amplitude P of backward Euler,
    (1 - e^{-i omega dt})/dt P = (D/h^2)(L P + 2 A e_top) (L the cells' second difference, the
    top face half a cell away, no flow at the base), which in the top cell is about 2 D/(h^2
    omega) = 3e-4 A (the exact field there, A e^{-28}, is no test at all). Fitted over the fifth
    period with a constant for the slowly decaying start (rate 3 D/h^2, 1.5 % over the run):
    every cell within 1 % of the top cell's amplitude."""
    k, A, n, height = 1.0e-12, 1.0e4, 50, 1.0
    diffusivity = k / (COMPRESSIBILITY * POROSITY * VISCOSITY)
    h = height / n
    period = 1e-3 * h * h / diffusivity
    omega = 2.0 * math.pi / period
    delta = math.sqrt(2.0 * diffusivity / omega)
    model = column(
        n, height, {"permeability": {"model": "constant", "value": k},
                    "top": {"amplitude": A, "period": period}, "bottom": {"type": "no-flow"}},
    )  # fmt: skip
    steps = 40
    dt = period / steps
    largest, samples = 0.0, []
    for step in range(1, 5 * steps + 1):
        model.advance(dt, step * dt)
        p = model.state.pressure[0, 0]
        largest = max(largest, float(np.abs(p).max()))
        if step > 4 * steps:
            samples.append(p.copy())
    t = np.arange(4 * steps + 1, 5 * steps + 1) * dt
    basis = np.stack([np.sin(omega * t), np.cos(omega * t), np.ones_like(t)], axis=1)
    (s, c, _), *_ = np.linalg.lstsq(basis, np.array(samples), rcond=None)
    rate = diffusivity / (h * h)
    system = np.diag(np.full(n, 2.0 * rate + (1.0 - np.exp(-1j * omega * dt)) / dt).astype(complex))
    system -= np.diag(np.full(n - 1, rate), 1) + np.diag(np.full(n - 1, rate), -1)
    system[0, 0] -= rate  # no flow through the base
    system[-1, -1] += rate  # the top face half a cell from the centre: twice the conductance
    forcing = np.zeros(n, dtype=complex)
    forcing[-1] = 2.0 * rate * A
    scheme = np.linalg.solve(system, forcing)
    top = float(abs(scheme[-1]))
    error = float(np.abs((s + 1j * c) - scheme).max()) / top
    finite = bool(np.all(np.isfinite(samples)))
    return _record(
        "ran",
        f"skin depth {delta / h:.3g} cells; max |p| = {largest / A:.2e} A; top cell amplitude "
        f"{float(np.hypot(s[-1], c[-1])) / A:.3e} A against the scheme's {top / A:.3e} A",
        [
            {"check": "finite", "passed": finite, "detail": ""},
            {"check": "bounded: |p| <= A", "passed": finite and largest <= A, "detail": f"{largest / A:.2e}"},
            {"check": "the scheme's periodic state within 1 % of the top cell's amplitude",
             "passed": finite and error < 0.01, "detail": f"{error:.2e}"},
        ],
        theory="backward Euler: unconditionally stable, no overshoot (an M-matrix each step)",
        limit=model.explicit_limit(),
    )  # fmt: skip


_register(
    StabilityCase(
        "stability-fluid-darcy-pulse-faster-than-diffusion",
        "Darcy: a top pressure pulsed 1000x faster than diffusion across one cell",
        "ran",
        darcy_pulse_faster_than_diffusion,
    )
)


# ------------------------------------------------------------------ porosity near 0


def porosity_near_zero_navier_stokes(quick: bool) -> dict:
    """A fixed bed of imposed porosity 0.01, below the drag laws' floor (fluid.drag.porosity_floor,
    0.1; Ergun diverges as porosity -> 0): refused before the run, naming the key and the floor."""
    try:
        bed_column(40, 5.0, 0.01, 1e-3, 1)
        error = None
    except SphereError as exc:
        error = exc
    return _refusal(
        error,
        ("fluid.bed.porosity", "porosity_floor"),
        "accepted a bed of porosity 0.01",
        "the drag laws' porosity floor",
        math.nan,
    )


_register(
    StabilityCase(
        "stability-fluid-porosity-near-zero-navier-stokes",
        "Navier-Stokes: a fixed bed of porosity 0.01, below the drag laws' floor",
        "refused",
        porosity_near_zero_navier_stokes,
    )
)


def porosity_near_zero_darcy(quick: bool) -> dict:
    """Steady seepage up a column whose lower half has porosity 1e-3 (a near-solid layer) and
    upper half 0.5, Kozeny-Carman: the lower half is raised to fluid.porosity_min = 0.1 (the
    documented clamp, counted), and the flux is that of the clamped layers in series to 1e-6."""
    n, height, kc, dp = 20, 0.1, 1.0e-9, 1.0e3
    model = column(
        n, height, {"permeability": {"coefficient": kc}, "top": {"pressure": 0.0}, "bottom": {"pressure": dp}}
    )
    model.state.porosity[0, 0, :] = np.where(np.arange(n) < n // 2, 1e-3, 0.5)
    model.advance(1.0e6, 1.0e6)
    k1, k2 = (kc * f**3 / (1 - f) ** 2 for f in (0.1, 0.5))
    exact = dp / height * (2 * k1 * k2 / (k1 + k2)) / VISCOSITY
    flux = (model.state.porosity_used * model.state.velocity[..., 2])[0, 0]
    error = float(np.max(np.abs(flux / exact - 1.0)))
    clamped = int(model.state.clamped_cells)
    return _record(
        "ran",
        f"{clamped} cells clamped to porosity 0.1; flux {float(flux.mean()):.4g} m/s, error {error:.1e}",
        [
            {"check": "the near-solid cells counted as clamped", "passed": clamped == n // 2,
             "detail": str(clamped)},
            {"check": "the flux of the clamped layers to 1e-6", "passed": error < 1e-6,
             "detail": f"{error:.1e}"},
        ],
        theory="porosity clamped to [porosity_min, porosity_max] in the fluid equations",
    )  # fmt: skip


_register(
    StabilityCase(
        "stability-fluid-porosity-near-zero-darcy",
        "Darcy: a layer of porosity 1e-3 under one of 0.5 (the clamp)",
        "ran",
        porosity_near_zero_darcy,
    )
)
