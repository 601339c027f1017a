"""Verification cases of the fluid models alone (group C): each against an analytic solution of
its own equations, over a ladder of grid resolutions, with the cost in cell (or layer) updates.

- 1D VANS (physics/fluid/vans1d.py FluidColumn): the laminar channel under a moving lid, and
  turbulent free-surface flow with each treatment of the viscous sublayer (none, van Driest,
  YADE's cut-off) against the exact solution of that same mixing-length form
  (vans1d_exact.py), not against the log law by habit.
- Navier-Stokes (physics/fluid/navier_stokes.py NavierStokesSolver): the decay rate of the
  Taylor-Green vortex; Ergun's pressure gradient through a fixed bed of imposed porosity, set up
  from a case file at dt = "auto".
- Darcy (physics/fluid/pore_pressure.py PorePressure): Terzaghi's consolidation, and steady
  seepage through two layers in series (darcy_reference.py).
"""

from __future__ import annotations

import math
import time

import numpy as np

from ..api import run_in_memory
from ..config.fluid_navier_stokes import NavierStokesFluid
from ..physics.fluid.grid import FluidGrid
from ..physics.fluid.navier_stokes import NavierStokesSolver
from ..physics.fluid.vans1d import FluidColumn
from ..simulation import advance
from . import vans1d_exact as exact
from .darcy_reference import (
    COMPRESSIBILITY,
    POROSITY,
    VISCOSITY,
    column,
    periodic_top_pressure,
    terzaghi_pressure,
)
from .registry import Outcome, Tolerance, VerificationCase, register

RHO = 1000.0  # water [kg/m^3]


def steady_profile(column: FluidColumn, solid, vel_p, exchange, source, dt, chunk=50, tol=1e-13) -> int:
    """Implicit steps of dt [s] until the profile changes by less than tol (relative) over a
    chunk of steps; returns the steps taken."""
    column.update_mixing_length(solid)
    for rounds in range(1, 401):
        before = column.u.copy()
        column.advance(solid, vel_p, exchange, source, dt, chunk)
        if np.abs(column.u - before).max() <= tol * max(np.abs(column.u).max(), 1e-300):
            return rounds * chunk
    raise RuntimeError("the profile did not become steady")


# ---------------------------------------------------------------------------------- 1D VANS

LID = 2.0  # m/s
DPDX = -0.1  # Pa/m
MU = 1e-3  # Pa s


def couette_poiseuille(cells: float) -> Outcome:
    """Laminar channel h = 1 m between the floor and a lid moving at LID, driven by DPDX: the
    steady solve (implicit, dt -> infinity) on layers stretched 4x towards the top."""
    n = int(cells)
    start = time.perf_counter()
    col = FluidColumn.regular(0.0, 1.0, n, 4.0, rho=RHO, nu=MU / RHO, top_no_slip=True, lid_velocity=LID)
    zero = np.zeros(n)
    col.update_mixing_length(zero)
    col.advance(zero, zero, zero, -DPDX, 1e12, 2)
    seconds = time.perf_counter() - start
    z = col.centres
    u = -DPDX / (2 * MU) * z * (1 - z) + LID * z
    error = float(np.abs(col.u - u).max() / u.max())
    return Outcome(
        dt=1e12, steps=2, particles=0, errors={"u_linf": error}, values={"u_top_layer": float(col.u[-1])},
        step_seconds=seconds, work=2 * n, work_unit="layer-update",
    )  # fmt: skip


register(
    VerificationCase(
        name="c1-vans1d-laminar-channel",
        title="C1 1D VANS laminar channel under a moving lid (Couette-Poiseuille)",
        model="vans1d",
        reference=(
            "u = (-dp/dx)/(2 mu) z (h - z) + U z/h, the sum of Poiseuille's and Couette's exact "
            "solutions (verification group C: 0.5 % at 100 layers)"
        ),
        description=(
            f"h = 1 m, mu = {MU} Pa s, dp/dx = {DPDX} Pa/m, lid at U = {LID} m/s (YADE's uTop), "
            "layers stretched 4x towards the lid; the steady profile of one implicit solve"
        ),
        run=couette_poiseuille,
        ladder=(25, 50, 100, 200),
        quick_ladder=(25, 50, 100),
        resolution="layers",
        error_labels={"u_linf": "max |u - exact| / max exact"},
        order_metrics=("u_linf",),
        formal_order=2.0,
        min_order=1.9,
        order_note="central fluxes on a smoothly stretched mesh",
        tolerances=(Tolerance("u_linf", 0.005, 100, source="verification group C"),),
    )
)


def free_surface(a_plus: float = 0.0, sublayer_plus: float = 0.0, mixing: str = "prandtl", dt: float = 0.02):
    """Steady turbulent free-surface flow down a 0.05 rad slope, depth 0.1 m, a mixing length
    (Prandtl's with van Driest's damping (a_plus) or YADE's sublayer cut-off (z+ =
    sublayer_plus); the parabolic one; Li & Sawamoto's through the smooth bed of
    vans1d_exact.bed_solid, held as the solid fraction at the layer centres, no drag), on layers
    stretched 1e4x upwards (the sublayer resolved); error against the exact solution of the
    same form. Implicit steps of dt [s] to the steady state (the bed's slow viscous diffusion,
    (30 mm)^2/nu = 900 s, takes long ones)."""

    def run(cells: float) -> Outcome:
        n = int(cells)
        sublayer = sublayer_plus * exact.NU / exact.U_STAR
        start = time.perf_counter()
        col = FluidColumn.regular(
            0.0, exact.DEPTH, n, 1e4, rho=RHO, nu=exact.NU, mixing=mixing, van_driest=a_plus,
            sublayer=sublayer, packed_solid_fraction=exact.PACKED,
        )  # fmt: skip
        zero = np.zeros(n)
        solid = exact.bed_solid(col.centres) if mixing == "li-sawamoto" else zero
        steps = steady_profile(col, solid, zero, zero, RHO * exact.G * math.sin(exact.SLOPE), dt=dt)
        seconds = time.perf_counter() - start
        u = exact.free_surface_velocity(mixing, col.centres, a_plus=a_plus, sublayer=sublayer)
        error = float(np.abs(col.u - u).max() / u.max())
        return Outcome(
            dt=dt, steps=steps, particles=0, errors={"u_linf": error},
            values={"surface_velocity": float(col.u[-1])}, step_seconds=seconds, work=steps * n,
            work_unit="layer-update",
        )  # fmt: skip

    return run


_TURBULENT = dict(
    model="vans1d",
    ladder=(50, 100, 200, 400),
    quick_ladder=(50, 100),
    resolution="layers",
    error_labels={"u_linf": "max |u - exact| / max exact, exact of the same mixing-length form"},
)
_SECOND_ORDER = dict(
    order_metrics=("u_linf",),
    formal_order=2.0,
    min_order=1.85,
    tolerances=(Tolerance("u_linf", 0.003, 100, source="verification group C"),),
)
_EXACT = (
    "the exact steady solution of the same mixing length, (nu + l^2 |u'|) u' = u*^2 (1 - s/H) "
    "integrated by Gauss-Legendre to 1e-12 (vans1d_exact.py)"
)
_SLOPE = (
    f"slope 0.05 rad, depth {exact.DEPTH} m, nu = {exact.NU} m^2/s, kappa = {exact.KAPPA}, "
    f"u* = {exact.U_STAR:.4f} m/s; 1e4x stretched layers from the smooth floor"
)

register(
    VerificationCase(
        name="c1-vans1d-prandtl",
        title="C1 1D VANS turbulent free-surface flow, Prandtl mixing length, no sublayer treatment",
        reference=_EXACT + " (verification group C)",
        description=_SLOPE + "; l = kappa z down to the floor",
        run=free_surface(),
        order_note="central fluxes, the sublayer resolved by the stretched mesh",
        **_TURBULENT,
        **_SECOND_ORDER,
    )
)

register(
    VerificationCase(
        name="c1-vans1d-van-driest",
        title="C1 1D VANS turbulent free-surface flow, van Driest damping (A+ = 26)",
        reference=_EXACT + ", l damped by 1 - exp(-z+/26) (van Driest 1956)",
        description=_SLOPE + "; u* from the largest shear stress of the previous step",
        run=free_surface(a_plus=26.0),
        order_note="central fluxes, the damped sublayer resolved by the stretched mesh",
        **_TURBULENT,
        **_SECOND_ORDER,
    )
)

register(
    VerificationCase(
        name="c1-vans1d-viscous-sublayer",
        title="C1 1D VANS turbulent free-surface flow, YADE's viscous sublayer (nu_t = 0 below z+ = 11.3)",
        reference=_EXACT + ", l = 0 below z+ = 11.3 (YADE HydroForceEngine viscousSubLayer)",
        description=_SLOPE + "; the cut falls at the faces below 11.3 nu/u*",
        run=free_surface(sublayer_plus=11.3),
        order_note=(
            "not checked: the cut falls at a face, up to one layer from 11.3 nu/u*, so the error "
            "does not fall smoothly (first order in the face's distance from it)"
        ),
        tolerances=(Tolerance("u_linf", 0.01, 50, source="the cut within one layer of its height"),),
        **_TURBULENT,
    )
)

register(
    VerificationCase(
        name="c1-vans1d-parabolic",
        title="C1 1D VANS turbulent free-surface flow, parabolic mixing length",
        reference=_EXACT + ", l = kappa s sqrt(1 - s/H) (vanishing at the free surface)",
        description=_SLOPE + "; no sublayer treatment",
        run=free_surface(mixing="parabolic"),
        order_note="central fluxes, the sublayer resolved by the stretched mesh",
        **_TURBULENT,
        **_SECOND_ORDER,
    )
)

register(
    VerificationCase(
        name="c1-vans1d-li-sawamoto",
        title="C1 1D VANS turbulent free-surface flow through a bed, Li & Sawamoto's mixing length",
        reference=(
            "the exact steady solution through a solid fraction c(s): (1 - c)(nu + l^2 |u'|) u' = g "
            "sin(alpha) int_s^H (1 - c), l = kappa int_0^s (1 - c/c_max) (Li & Sawamoto 1995), "
            "integrated by Gauss-Legendre to 1e-12 (vans1d_exact.py)"
        ),
        description=(
            _SLOPE + "; a smooth bed c = 0.25 (1 - tanh((s - 30 mm)/10 mm)), c_max = 0.61, held as "
            "the layers' solid fraction without drag (the mixing length and the (1 - c) factors "
            "alone); implicit steps of 1 s to the steady state"
        ),
        run=free_surface(mixing="li-sawamoto", dt=1.0),
        order_note="the solid fraction's midpoint integral, central fluxes, (1 - c) interpolated at faces",
        **_TURBULENT,
        **_SECOND_ORDER,
    )
)


# ---------------------------------------------------------------------------------- Navier-Stokes


def register_solver_variants(name: str, title: str, setup: str, factory, common: dict) -> None:
    """Register a case twice: solved by conjugate gradients (the default, as `name`) and by Jacobi
    iteration (the original sphere's, as `name`-jacobi) to the same tolerance, whose errors are
    the same and whose cost the work-precision plot sets side by side."""
    register(
        VerificationCase(
            name=name, title=title, description=setup + "; solved by conjugate gradients (the default)",
            run=factory("pcg"), **common,
        )
    )  # fmt: skip
    register(
        VerificationCase(
            name=f"{name}-jacobi", title=title + ", with the Jacobi solver",
            description=(
                setup + '; solved by Jacobi iteration ([fluid.solver] method = "jacobi") to the same '
                "tolerance: the same errors, at its own cost"
            ),
            run=factory("jacobi"), **common,
        )
    )  # fmt: skip


def ns_solver(shape, length, gravity=(0.0, 0.0, 0.0), **fluid) -> NavierStokesSolver:
    """The Navier-Stokes solver alone on `shape` cells filling a box of `length` [m] (x, y
    periodic), water unless `fluid` (the [fluid] keys) says otherwise, under `gravity` [m/s^2]."""
    spacing = np.asarray(length, dtype=float) / np.asarray(shape)
    grid = FluidGrid(
        origin=np.zeros(3), spacing=spacing, shape=tuple(shape), periodic=np.array([True, True, False])
    )
    config = NavierStokesFluid.model_validate({"model": "navier-stokes", "density": RHO, **fluid})
    return NavierStokesSolver(config, grid, gravity)


CLOSED = {"bottom": {"type": "no-flow"}, "top": {"type": "no-flow"}}


def timed_steps(solver: NavierStokesSolver, fs, steps: int, dt: float) -> float:
    """`steps` fluid steps of dt [s] from t = 0; the wall time they took [s]."""
    start = time.perf_counter()
    for step in range(steps):
        solver.step(fs, step * dt, dt)
    return time.perf_counter() - start


def taylor_green(method: str = "pcg"):
    """The Taylor-Green case below with the pressure solved by `method` ("pcg" or "jacobi")."""

    def run(cells: float) -> Outcome:
        return taylor_green_rate_error(cells, method)

    return run


def taylor_green_rate_error(cells: float, method: str = "pcg") -> Outcome:
    """Relative error of the decay rate of the Taylor-Green vortex (one wavelength L = 1 m on
    `cells` x `cells` cells, two layers along z between free-slip walls) against 2 nu k^2, over
    t = 0.1/(2 nu k^2) at dt = 0.25 of the viscous limit. A = 1e-3 m/s, nu = 1e-3 m^2/s: the
    Reynolds number A L/nu = 1, the vortex's nonlinear term is a pure gradient (balanced by the
    pressure p = -rho A^2/4 (cos 2kx + cos 2ky)), and the discrete advection's departure from it
    is O(A dx) against the viscous O(nu k^2). The error is signed (values) and absolute (errors)."""
    n = int(cells)
    nu, amplitude = 1e-3, 1e-3
    solver = ns_solver(
        (n, n, 2), (1.0, 1.0, 2.0 / n), viscosity=nu * RHO, solver={"method": method}, **CLOSED
    )
    fs = solver.allocate()
    k = 2 * math.pi
    x, y, _ = solver.face_coordinates(0)
    u0 = amplitude * np.sin(k * x) * np.cos(k * y)
    x, y, _ = solver.face_coordinates(1)
    v0 = -amplitude * np.cos(k * x) * np.sin(k * y)
    solver.set_velocity(fs, (u0, v0, 0.0))
    duration = 0.1 / (2 * nu * k * k)
    steps = math.ceil(duration / (0.25 * solver.viscous_limit()))
    dt = duration / steps
    seconds = timed_steps(solver, fs, steps, dt)
    shape = np.broadcast_to(u0, fs.v_face[..., :-1, 0].shape)
    measured = float((fs.v_face[..., :-1, 0] * shape).sum() / (shape * shape).sum())
    # 2D to the pressure solve's tolerance (1e-10 relative), not bit for bit: the red-black
    # smoothing of its multigrid (from 64 cells) updates the two layers in turn (2e-19 m/s at 64)
    if np.abs(fs.v_face[..., 2]).max() > 1e-9 * amplitude:
        raise RuntimeError("the 2D vortex grew a vertical velocity")
    error = -math.log(measured) / duration / (2 * nu * k * k) - 1.0
    return Outcome(
        dt=dt, steps=steps, particles=0, errors={"rate": abs(error)}, values={"rate_error": error},
        step_seconds=seconds, work=steps * n * n * 2, work_unit="cell-update",
    )  # fmt: skip


_TAYLOR_GREEN = dict(
    model="navier-stokes",
    reference=(
        "u = A sin(kx) cos(ky) e^{-2 nu k^2 t} (Taylor & Green 1937): the rate 2 nu k^2; the "
        "MAC grid's second differences give 2 nu k^2 (1 - (k dx)^2/12)"
    ),
    ladder=(16, 32, 64),
    quick_ladder=(16, 32),
    resolution="cells per wavelength",
    error_labels={"rate": "|measured rate / 2 nu k^2 - 1|"},
    order_metrics=("rate",),
    formal_order=2.0,
    min_order=1.9,
    order_note=(
        "second-order differences; forward Euler's error at a fixed fraction of the viscous "
        "limit falls as dx^2 too"
    ),
    tolerances=(Tolerance("rate", 0.01, 32, source="issue acceptance: 1 % at 32 cells per wavelength"),),
)
_TG_SETUP = (
    "one wavelength of 1 m, A = 1e-3 m/s, nu = 1e-3 m^2/s (Reynolds number 1), two layers "
    "between free-slip walls, over 0.1 of the decay time at a quarter of the viscous limit"
)

register_solver_variants(
    "c2-ns-taylor-green",
    "C2 Navier-Stokes: decay rate of the Taylor-Green vortex",
    _TG_SETUP,
    taylor_green,
    _TAYLOR_GREEN,
)


def shear_wave(phi: float = 1.0, formulation: str = "A"):
    """The decaying shear wave u_x = A sin(k y) (A = 1e-3 m/s, one wavelength of 1 m along y,
    nu = 1e-3 m^2/s) through a uniform porosity phi, over t = 0.2/(nu k^2) at dt = 0.1 of the
    viscous limit: the relative error of its decay rate against nu k^2 (signed in values)."""

    def run(cells: float) -> Outcome:
        n = int(cells)
        nu, amplitude = 1e-3, 1e-3
        dy = 1.0 / n
        solver = ns_solver(
            (2, n, 3), (2 * dy, 1.0, 3 * dy), viscosity=nu * RHO, formulation=formulation, **CLOSED
        )
        fs = solver.allocate()
        fs.porosity[...] = phi
        k = 2 * math.pi
        profile = np.sin(k * solver.grid.centres(1))
        solver.set_velocity(fs, (amplitude * profile[None, :, None], 0.0, 0.0))
        duration = 0.2 / (nu * k * k)
        steps = math.ceil(duration / (0.1 * solver.viscous_limit()))
        dt = duration / steps
        seconds = timed_steps(solver, fs, steps, dt)
        measured = 2.0 / n * float(fs.v_face[0, :, 1, 0] @ profile)  # the wave keeps its shape
        if np.abs(fs.v_face[..., 1:]).max() != 0.0:
            raise RuntimeError("the shear wave grew a v_y or v_z")
        error = -math.log(measured / amplitude) / duration / (nu * k * k) - 1.0
        return Outcome(
            dt=dt, steps=steps, particles=0, errors={"rate": abs(error)}, values={"rate_error": error},
            step_seconds=seconds, work=steps * 6 * n, work_unit="cell-update",
        )  # fmt: skip

    return run


_WAVE = dict(
    model="navier-stokes",
    ladder=(16, 32, 64, 128),
    quick_ladder=(16, 32),
    resolution="cells per wavelength",
    error_labels={"rate": "|measured rate / nu k^2 - 1|"},
    order_metrics=("rate",),
    formal_order=2.0,
    min_order=1.9,
    order_note=(
        "the 3-point second difference, nu k^2 (1 - (k dy)^2/12); forward Euler at 0.1 of the "
        "viscous limit adds 0.1 (k dy)^2/16"
    ),
    tolerances=(Tolerance("rate", 0.01, 32, source="verification group C: 1 % at 32 cells per wavelength"),),
)

register(
    VerificationCase(
        name="c2-ns-shear-wave",
        title="C2 Navier-Stokes: decay rate of a shear wave",
        reference=(
            "u_x = A sin(ky) e^{-nu k^2 t}, the exact solution of the unsteady Stokes (and "
            "Navier-Stokes) equations"
        ),
        description="one wavelength of 1 m, A = 1e-3 m/s, nu = 1e-3 m^2/s, porosity 1, over 0.2 decay times",
        run=shear_wave(),
        **_WAVE,
    )
)

register(
    VerificationCase(
        name="c2-ns-shear-wave-porous",
        title="C2 Navier-Stokes: decay rate of a shear wave through a uniform porosity 0.4 (formulation B)",
        reference=(
            "the same rate nu k^2 as in clear fluid: (1/phi) div(phi tau) = div(tau) when phi is "
            "uniform (verification group C: unchanged for uniform porosity)"
        ),
        description="the c2-ns-shear-wave set-up at porosity 0.4, formulation B (pressure in the fluid only)",
        run=shear_wave(0.4, "B"),
        **_WAVE,
    )
)


def kolmogorov(cells: float) -> Outcome:
    """Kolmogorov flow: a body-force field g_x = F sin(ky) (F = 1e-3 m/s^2, one wavelength of 1
    m along y, nu = 1e-2 m^2/s) on fluid at rest, after 8 viscous times 1/(nu k^2): the largest
    difference from the steady u = F sin(ky)/(nu k^2), relative to its amplitude."""
    n = int(cells)
    nu, force = 1e-2, 1e-3
    dy = 1.0 / n
    solver = ns_solver((2, n, 2), (2 * dy, 1.0, 2 * dy), viscosity=nu * RHO, **CLOSED)
    fs = solver.allocate()
    k = 2 * math.pi
    _, y, _ = solver.face_coordinates(0)
    fs.acceleration[..., :-1, 0] = force * np.sin(k * y)
    duration = 8.0 / (nu * k * k)
    steps = math.ceil(duration / (0.5 * solver.viscous_limit()))
    dt = duration / steps
    seconds = timed_steps(solver, fs, steps, dt)
    if np.abs(fs.v_face[..., 1:]).max() != 0.0:
        raise RuntimeError("the forced shear flow grew a v_y or v_z")
    exact = np.broadcast_to(force * np.sin(k * y) / (nu * k * k), fs.v_face[..., :-1, 0].shape)
    error = float(np.abs(fs.v_face[..., :-1, 0] - exact).max() / np.abs(exact).max())
    return Outcome(
        dt=dt, steps=steps, particles=0, errors={"u_linf": error}, step_seconds=seconds,
        work=steps * 4 * n, work_unit="cell-update",
    )  # fmt: skip


register(
    VerificationCase(
        name="c2-ns-kolmogorov-flow",
        title="C2 Navier-Stokes: a channel driven by a body-force field (Kolmogorov flow)",
        model="navier-stokes",
        reference="u = F sin(ky)/(nu k^2), the steady flow of the forcing g_x = F sin(ky)",
        description=(
            "F = 1e-3 m/s^2, one wavelength of 1 m, nu = 1e-2 m^2/s, from rest, after 8 viscous "
            "times (the transient e^-8 = 3e-4 of it left)"
        ),
        run=kolmogorov,
        ladder=(16, 32, 64),
        quick_ladder=(16, 32),
        resolution="cells per wavelength",
        error_labels={"u_linf": "max |u - exact| / F/(nu k^2)"},
        order_metrics=("u_linf",),
        formal_order=2.0,
        min_order=1.8,
        order_note="the 3-point second difference, 1 - (k dy)^2/12, until the transient's 3e-4 floor",
        tolerances=(
            Tolerance("u_linf", 0.01, 32, source="issue 22 acceptance: 1 % of the analytic profile"),
        ),
    )
)


HYDROSTATIC_TOP = 100.0  # Pa


def hydrostatic(cells: float) -> Outcome:
    """Water at rest in a closed-bottom column H = 0.1 m (2 x 2 x `cells` cells) open at the top
    at 100 Pa, porosity 0.4 below mid-height and 1 above, gravity 9.81 m/s^2, started with p = 0
    and run 20 steps of a quarter of the viscous limit, in formulations A and B: the pressure
    against the hydrostatic one of each, relative to rho g H, and the largest velocity relative
    to g dt (what one step of gravity alone would give)."""
    n = int(cells)
    height, g = 0.1, 9.81
    errors, values, seconds, steps = {}, {}, 0.0, 20
    for formulation in ("A", "B"):
        solver = ns_solver(
            (2, 2, n), (2 * height / n, 2 * height / n, height), gravity=(0.0, 0.0, -g),
            formulation=formulation, bottom={"type": "no-flow"},
            top={"type": "pressure", "pressure": HYDROSTATIC_TOP},
        )  # fmt: skip
        fs = solver.allocate()
        z = solver.grid.centres(2)
        phi = np.where(z < 0.5 * height, 0.4, 1.0)
        fs.porosity[...] = phi[None, None, :]
        solver.set_velocity(fs, (0.0, 0.0, 0.0))
        dt = 0.25 * solver.viscous_limit()
        seconds += timed_steps(solver, fs, steps, dt)
        if formulation == "A":  # the pressure acts in both phases: the pores' hydrostatic pressure
            weight = height - z
        else:  # in the fluid only: the fluid's weight per total area above z, rho g int phi dz
            dz = height / n
            weight = 0.5 * phi * dz + (np.cumsum(phi[::-1])[::-1] - phi) * dz
        exact = HYDROSTATIC_TOP + RHO * g * weight
        errors[f"p_{formulation}"] = float(np.abs(fs.p - exact[None, None, :]).max() / (RHO * g * height))
        errors[f"v_{formulation}"] = float(np.abs(fs.v_face).max() / (g * dt))
        values[f"bottom_pressure_{formulation}"] = float(fs.p[0, 0, 0])
    return Outcome(
        dt=dt, steps=steps, particles=0, errors=errors, values=values, step_seconds=seconds,
        work=2 * steps * 4 * n, work_unit="cell-update",
    )  # fmt: skip


register(
    VerificationCase(
        name="c2-ns-hydrostatic",
        title="C2 Navier-Stokes: a column at rest through a porosity step (hydrostatic balance)",
        model="navier-stokes",
        reference=(
            "dp/dz = -rho g in formulation A (-phi grad p + phi rho g = 0) and dp/dz = -phi rho g in "
            "B (-grad p + phi rho g = 0), no flow; exact on the MAC grid, whose pressure gradient "
            "and face porosity sit at the same faces"
        ),
        description=(
            "water, H = 0.1 m, closed base, top open at 100 Pa, porosity 0.4 below mid-height and "
            "1 above, from p = 0; 20 steps of a quarter of the viscous limit"
        ),
        run=hydrostatic,
        ladder=(10, 20, 40, 80),
        quick_ladder=(10, 20),
        resolution="cells along z",
        error_labels={
            "p_A": "max |p - hydrostatic| / (rho g H), formulation A",
            "v_A": "max |v| / (g dt), formulation A",
            "p_B": "max |p - hydrostatic| / (rho g H), formulation B",
            "v_B": "max |v| / (g dt), formulation B",
        },
        order_note="not a convergence case: the balance is exact, to the pressure solver's tolerance (1e-10)",
        tolerances=tuple(
            Tolerance(metric, 1e-8, source="the solver's tolerance 1e-10 times the column's condition")
            for metric in ("p_A", "v_A", "p_B", "v_B")
        ),
    )
)

BED_COLUMN = """
[simulation]
duration = 100.0
[domain]
upper = [0.002, 0.002, 0.04]
periodic = [true, true, false]
gravity = [0.0, 0.0, 0.0]
[fluid]
model = "navier-stokes"
grid = {{ cells = [2, 2, {cells}] }}
bottom = {bottom}
top = {{ type = "pressure", pressure = 0.0 }}
[fluid.bed]
porosity = {porosity!r}
diameter = {diameter!r}
lower = 0.01
upper = 0.03
"""


def bed_column(cells: int, pressure: float, porosity: float, diameter: float, steps: int):
    """Water driven up a column 40 mm high (2 x 2 x `cells` cells) by `pressure` [Pa] through a
    fixed bed of `porosity` and grains of `diameter` [m] between 10 and 30 mm ([fluid.bed]),
    dt = "auto", gravity off, after `steps` steps: (the scene, the time spent stepping [s], the
    superficial velocity through the bed [m/s], the pressure gradient across its middle half
    [Pa/m], Ergun's at that velocity [Pa/m])."""
    bottom = f'{{ type = "pressure", pressure = {pressure!r} }}'
    text = BED_COLUMN.format(cells=cells, bottom=bottom, porosity=porosity, diameter=diameter)
    scene = run_in_memory(text, 0)
    start = time.perf_counter()
    advance(scene, steps)
    seconds = time.perf_counter() - start
    fs = scene.state.fluid
    superficial = float(porosity * fs.v_face[:, :, cells // 2, 2].mean())
    lower, upper = round(0.375 * cells), round(0.625 * cells)  # cell centres in the bed's middle
    gradient = float(fs.p[:, :, lower].mean() - fs.p[:, :, upper].mean()) / ((upper - lower) * 0.04 / cells)
    eps, mu = porosity, 1e-3
    ergun = 150 * mu * (1 - eps) ** 2 * superficial / (eps**3 * diameter**2) + 1.75 * RHO * (
        1 - eps
    ) * superficial**2 / (eps**3 * diameter)
    return scene, seconds, superficial, gradient, ergun


def ergun_bed(cells: float) -> Outcome:
    """The bed column at porosity 0.4 with grains of 0.6 mm driven by 50 Pa, dt = "auto" (the
    viscous limit, 100 times the bed's drag relaxation time at 40 cells), after 50 (cells/40)^2
    steps: the gradient across the bed's middle against Ergun's at the flow through it."""
    n = int(cells)
    steps = round(50 * (n / 40) ** 2)
    scene, seconds, superficial, gradient, ergun = bed_column(n, 50.0, 0.4, 6e-4, steps)
    return Outcome(
        dt=scene.state.clock.dt, steps=steps, particles=0, errors={"gradient": abs(gradient / ergun - 1.0)},
        values={"superficial_velocity": superficial, "gradient": gradient}, step_seconds=seconds,
        work=steps * 4 * n, work_unit="cell-update",
    )  # fmt: skip


register(
    VerificationCase(
        name="c2-ns-ergun-bed",
        title="C2 Navier-Stokes: Ergun's pressure gradient through a fixed bed at dt = auto",
        model="navier-stokes",
        reference=(
            "dP/L = 150 mu (1-eps)^2 U/(eps^3 d^2) + 1.75 rho (1-eps) U^2/(eps^3 d) (Ergun 1952); "
            "verification group D: 1 % with imposed porosity"
        ),
        description=(
            "a bed of imposed porosity 0.4, grains 0.6 mm, 20 mm thick in a 40 mm column of water "
            "driven by 50 Pa; the drag implicit in the fluid at 100x its relaxation time"
        ),
        run=ergun_bed,
        ladder=(20, 40, 80),
        quick_ladder=(20, 40),
        resolution="cells along z",
        error_labels={"gradient": "|gradient across the bed's middle / Ergun's at the flow - 1|"},
        order_note="not a convergence case: uniform inside the bed, the steady state is exact to round-off",
        tolerances=(Tolerance("gradient", 1e-6, source="exact inside a uniform bed at steady state"),),
    )
)


# ---------------------------------------------------------------------------------- Darcy

TERZAGHI_T = 0.2  # time factor D t/H^2 of the comparison


def terzaghi(method: str = "pcg"):
    """The Terzaghi case below with the implicit solve by `method` ("pcg" or "jacobi"), or the
    explicit scheme ("explicit")."""

    def run(cells: float) -> Outcome:
        return terzaghi_error(cells, method)

    return run


def terzaghi_error(cells: float, method: str = "pcg") -> Outcome:
    """Terzaghi consolidation of a 1 m layer (drained top, impermeable base, p0 = 1e4 Pa) on
    `cells` layers, backward Euler at 10x the explicit limit h^2/(2D) (so dt falls as h^2 and
    the time error with the space error), or forward Euler (method "explicit") at 0.9 of it,
    compared at T = TERZAGHI_T."""
    n = int(cells)
    height, p0 = 1.0, 1.0e4
    explicit = method == "explicit"
    fluid = {
        "permeability": {"model": "constant", "value": 1e-12},
        "initial_pressure": p0,
        "bottom": {"type": "no-flow"},
    }
    if explicit:
        fluid["time_scheme"] = "explicit"
    else:
        fluid["solver"] = {"method": method, "tolerance": 1e-12}
    model = column(n, height, fluid)
    diffusivity = 1e-12 / (COMPRESSIBILITY * POROSITY * VISCOSITY)
    steps = round(
        TERZAGHI_T * height**2 / diffusivity / ((0.9 if explicit else 10.0) * model.explicit_limit())
    )
    dt = TERZAGHI_T * height**2 / diffusivity / steps
    start = time.perf_counter()
    for step in range(1, steps + 1):
        model.advance(dt, step * dt)
    seconds = time.perf_counter() - start
    depth = height - model.grid.centres(2)
    p = model.state.pressure[0, 0]
    error = float(np.max(np.abs(p - terzaghi_pressure(depth, TERZAGHI_T, p0, height))) / p0)
    return Outcome(
        dt=dt, steps=steps, particles=0, errors={"p_linf": error},
        values={"consolidation": float(1.0 - p.mean() / p0)}, step_seconds=seconds, work=steps * n,
        work_unit="cell-update",
    )  # fmt: skip


_TERZAGHI = dict(
    model="darcy",
    reference=(
        "p = sum 2 p0/M sin(M z'/H) exp(-M^2 T), M = (2m + 1) pi/2 (Terzaghi 1943; Verruijt, "
        "Soil Mechanics 2012, ch. 15); verification group C: 1 % of p0"
    ),
    ladder=(25, 50, 100, 200),
    quick_ladder=(25, 50),
    resolution="cells",
    error_labels={"p_linf": "max |p - exact| / p0"},
    order_metrics=("p_linf",),
    formal_order=2.0,
    min_order=1.8,
    order_note="second-order space; backward Euler's first-order time error falls as dt ~ dx^2",
    tolerances=(Tolerance("p_linf", 0.01, 25, source="verification group C"),),
)
_TERZAGHI_SETUP = (
    "a 1 m layer, k = 1e-12 m^2, water, porosity 0.4, a rigid skeleton; drained top, "
    "impermeable base, p0 = 1e4 Pa; at T = 0.2, backward Euler at 10x the explicit limit"
)

register_solver_variants(
    "c3-darcy-terzaghi",
    "C3 Darcy: Terzaghi consolidation of a drained layer",
    _TERZAGHI_SETUP,
    terzaghi,
    _TERZAGHI,
)
register(
    VerificationCase(
        name="c3-darcy-terzaghi-explicit",
        title="C3 Darcy: Terzaghi consolidation of a drained layer, with the explicit scheme",
        description=(
            _TERZAGHI_SETUP.replace(
                "backward Euler at 10x the explicit limit", "forward Euler at 0.9 of its limit"
            )
            + ' ([fluid] time_scheme = "explicit"): no solve a step, 11 times the steps'
        ),
        run=terzaghi("explicit"),
        **{
            **_TERZAGHI,
            "order_note": "second-order space; forward Euler's first-order time error falls as dt ~ dx^2",
        },
    )
)


def two_layers(cells: float) -> Outcome:
    """Steady seepage up a 0.1 m column of two layers of porosity 0.3 and 0.5 (Kozeny-Carman,
    k_c = 1e-9 m^2), equal thickness, 1 kPa across it, one backward-Euler step long enough to be
    steady: the flux in every cell against that of the harmonic-mean permeability."""
    n = int(cells)
    height, kc, dp = 0.1, 1.0e-9, 1.0e3
    model = column(
        n, height, {"permeability": {"coefficient": kc}, "top": {"pressure": 0.0}, "bottom": {"pressure": dp}}
    )
    model.state.porosity[0, 0, :] = np.where(np.arange(n) < n // 2, 0.3, 0.5)
    start = time.perf_counter()
    model.advance(1.0e6, 1.0e6)
    seconds = time.perf_counter() - start
    k1, k2 = (kc * f**3 / (1 - f) ** 2 for f in (0.3, 0.5))
    exact_flux = dp / height * (2 * k1 * k2 / (k1 + k2)) / VISCOSITY
    flux = (model.state.porosity_used * model.state.velocity[..., 2])[0, 0]
    return Outcome(
        dt=1.0e6, steps=1, particles=0, errors={"flux": float(np.max(np.abs(flux / exact_flux - 1.0)))},
        values={"flux": float(flux.mean())}, step_seconds=seconds, work=n, work_unit="cell-update",
    )  # fmt: skip


register(
    VerificationCase(
        name="c3-darcy-two-layers",
        title="C3 Darcy: steady seepage through two layers in series",
        model="darcy",
        reference=(
            "q = (dP/H) 2 k1 k2/(k1 + k2)/mu, the series resistance of the layers (Darcy 1856); "
            "verification group C"
        ),
        description=(
            "porosities 0.3 and 0.5 (Kozeny-Carman), equal thickness, 0.1 m, 1 kPa across; the "
            "Darcy flux from the face fluxes in every cell, the interface cells included"
        ),
        run=two_layers,
        ladder=(10, 20, 40, 80),
        quick_ladder=(10, 20),
        resolution="cells",
        error_labels={"flux": "max over the cells |q / q_exact - 1|"},
        order_note="not a convergence case: harmonic face permeabilities make the steady flux exact",
        tolerances=(Tolerance("flux", 1e-6, source="exact: the solver tolerance"),),
    )
)


SKIN_DEPTHS = 4  # layer height / skin depth of the periodic case


def periodic_top(per_skin_depth: float) -> Outcome:
    """Top pressure A sin(omega t) over a layer 4 skin depths deep (no flow at the base),
    `per_skin_depth` cells per skin depth delta = sqrt(2 D / omega), 2 per_skin_depth^2 steps a
    period (dt ~ dx^2), started from the exact periodic state and run two periods; amplitude and
    phase fitted over the second period. Errors: the largest pressure difference at the end,
    and the amplitude (relative to A) and phase [rad] at the cell nearest one skin depth."""
    c = int(per_skin_depth)
    k, A, period = 1.0e-12, 1.0e4, 1.0
    omega = 2 * math.pi / period
    diffusivity = k / (COMPRESSIBILITY * POROSITY * VISCOSITY)
    delta = math.sqrt(2 * diffusivity / omega)
    height = SKIN_DEPTHS * delta
    model = column(
        SKIN_DEPTHS * c, height, {"permeability": {"model": "constant", "value": k},
                                   "top": {"amplitude": A, "period": period}, "bottom": {"type": "no-flow"}},
    )  # fmt: skip
    z = model.grid.centres(2)
    exact = periodic_top_pressure(z, height, A, delta)
    model.state.pressure[0, 0] = exact.imag  # the periodic state at t = 0
    steps = 2 * c * c
    dt = period / steps
    times, samples = np.arange(steps + 1, 2 * steps + 1) * dt, []
    start = time.perf_counter()
    for step in range(1, 2 * steps + 1):
        model.advance(dt, step * dt)
        if step > steps:
            samples.append(model.state.pressure[0, 0].copy())
    seconds = time.perf_counter() - start
    end = float(np.abs(model.state.pressure[0, 0] - exact.imag).max() / A)  # t = 2 periods: phase 0
    basis = np.stack([np.sin(omega * times), np.cos(omega * times)], axis=1)
    (s, co), *_ = np.linalg.lstsq(basis, np.array(samples), rcond=None)
    cell = int(np.argmin(np.abs(height - z - delta)))
    amplitude, phase = float(np.hypot(s[cell], co[cell])), float(np.arctan2(co[cell], s[cell]))
    return Outcome(
        dt=dt, steps=2 * steps, particles=0,
        errors={"p_linf": end, "amplitude": abs(amplitude - abs(exact[cell])) / A,
                "phase": abs(phase - float(np.angle(exact[cell])))},
        values={"amplitude_at_skin_depth": amplitude / A, "lag_at_skin_depth": -phase},
        step_seconds=seconds, work=2 * steps * SKIN_DEPTHS * c, work_unit="cell-update",
    )  # fmt: skip


register(
    VerificationCase(
        name="c3-darcy-periodic-top",
        title="C3 Darcy: a sinusoidal pressure on the top of a layer (skin depth, amplitude and phase)",
        model="darcy",
        reference=(
            "p = Im[A cosh(lambda z)/cosh(lambda H) e^{i omega t}], lambda = (1 + i)/delta, delta = "
            "sqrt(2 D/omega) (Carslaw & Jaeger 1959, sec. 2.6): at one skin depth below the top "
            "about A/e, lagging by 1 rad"
        ),
        description=(
            "k = 1e-12 m^2, water, porosity 0.4 (D = 5.6e-3 m^2/s), A = 1e4 Pa, period 1 s "
            "(delta = 42 mm), a layer of 4 delta, impermeable base; backward Euler with 2 c^2 "
            "steps a period on c cells per skin depth"
        ),
        run=periodic_top,
        ladder=(5, 10, 20, 40),
        quick_ladder=(5, 10),
        resolution="cells per skin depth",
        error_labels={
            "p_linf": "max |p - exact| / A after two periods",
            "amplitude": "|fitted amplitude - exact| / A at one skin depth",
            "phase": "|fitted phase - exact| at one skin depth [rad]",
        },
        order_metrics=("p_linf", "amplitude", "phase"),
        formal_order=2.0,
        min_order=1.8,
        order_note=(
            "second-order space; backward Euler turns i omega into i omega (1 - i omega dt/2), "
            "first order in dt ~ dx^2"
        ),
        tolerances=(
            Tolerance("p_linf", 0.01, 10, source="verification group C: 1 % of the forcing"),
            Tolerance("phase", 0.01, 10, source="a hundredth of the 1 rad lag at one skin depth"),
        ),
    )
)
