"""Benchmark of the Darcy model coupled to the DEM (never part of the tests): the time of one
coupled step on a 64^3 fluid grid with 20 000 particles, and of its parts, with the implicit
solve's iterations.

    sphere bench darcy [--cells 64] [--particles 20000] [--threads 1,2] [--steps 20]

The scene: a box of 64 x 64 x 64 cells of 2 mm (periodic in x and y), 20 000 spheres of 1 mm
diameter on a jittered lattice filling it (a suspension: every cell's sampling sphere sees
particles), water, Kozeny-Carman permeability, an upward seepage of half the critical gradient
(bottom face held at an excess pressure, top drained), linear contacts, dt = 4e-6 s, the fluid
advanced every step. The first
coupled steps (compilation or cache loading, and the cold solve from p = 0) are timed apart;
the rows are medians over `steps` steps.
"""

from __future__ import annotations

import math
import statistics
import time

import numba

from ..config.load import parse_case
from ..scene.builder import build_scene
from . import Stopwatch, timed_steps

DIAMETER = 1.0e-3  # [m]
CELL = 2.0e-3  # [m]: two diameters
DENSITY = 2650.0  # [kg/m^3] quartz


def scene_text(cells: int, particles: int, spacing: float, jitter: float) -> str:
    """The particles and box of the coupled benchmarks (no [fluid] table): a cube of `cells`^3
    cells of CELL, periodic in x and y, DIAMETER spheres of DENSITY on a lattice of `spacing`
    diameters with `jitter`, linear contacts, a floor, dt = 4e-6 s."""
    width = cells * CELL
    return f"""
[simulation]
duration = 1.0
dt = 4.0e-6
stability = "contact"
[domain]
upper = [{width!r}, {width!r}, {width!r}]
periodic = [true, true, false]
[particles]
count = {particles}
density = {DENSITY!r}
radius = {{ distribution = "fixed", value = {DIAMETER / 2!r} }}
placement = {{ method = "lattice", spacing = {spacing!r}, jitter = {jitter!r} }}
[contact]
model = "linear"
normal_stiffness = 1.0e3
[[walls]]
face = "z-"
"""


def case_text(cells: int, particles: int, tolerance: float, coupling_steps: int = 1) -> str:
    width = cells * CELL
    per_side = math.ceil(particles ** (1.0 / 3.0))
    spacing = 0.99 * width / per_side / DIAMETER
    pressure = 0.5 * (DENSITY - 1000.0) * 9.81 * width  # half the critical gradient across the box
    return (
        scene_text(cells, particles, spacing, 0.5)
        + f"""[fluid]
model = "darcy"
grid = {{ cells = [{cells}, {cells}, {cells}] }}
bottom = {{ pressure = {pressure!r} }}
coupling = {{ steps = {coupling_steps} }}
solver = {{ tolerance = {tolerance!r} }}
"""
    )


def run_darcy_benchmark(
    cells: int = 64,
    particles: int = 20_000,
    threads=(1, 2),
    steps: int = 20,
    tolerance: float = 1e-8,
    log=print,
) -> None:
    """Log the timings of the module docstring, one row per thread count."""
    start = time.perf_counter()
    scene = build_scene(parse_case(case_text(cells, particles, tolerance)))
    scene.fluid.step_threads = None  # every part on the row's threads (runtime.grid_threads)
    build = time.perf_counter() - start
    fluid, state = scene.fluid, scene.state
    first = timed_steps(scene, 1)[0][0]
    cold = fluid.pore.state.iterations
    log(f"numba {numba.__version__} ({numba.threading_layer()} threading layer)")
    log(
        f"{cells}^3 cells, {state.particles.count} particles; build {build:.2f} s; first coupled step "
        f"{first:.2f} s (compile or cache load, and the cold solve from p = 0: {cold} iterations)"
    )
    log(
        "threads | coupled step [ms] wall (CPU) | porosity [ms] wall (CPU) | pressure step [ms] wall (CPU) | "
        "solve iterations | forces [ms] wall (CPU) | DEM alone [ms] wall"
    )
    med = statistics.median
    for count in threads:
        numba.set_num_threads(count)
        timed_steps(scene, 2)
        watches = [
            Stopwatch(fluid, "_measure"),
            Stopwatch(fluid.pore, "advance"),
            Stopwatch(fluid, "forces", scene),
        ]
        iterations, step_wall, step_cpu = [], [], []
        for _ in range(steps):
            wall, cpu = timed_steps(scene, 1)
            step_wall += wall
            step_cpu += cpu
            iterations.append(fluid.pore.state.iterations)
        for watch in watches:
            watch.restore()
        scene.fluid = None  # the same steps without the fluid: contacts, walls, integration
        scene.order_modules()
        dem = timed_steps(scene, steps)[0]
        scene.fluid = fluid
        scene.order_modules()
        porosity, solve, forces = (med(w.seconds) for w in watches)
        porosity_cpu, solve_cpu, forces_cpu = (med(w.cpu) for w in watches)
        log(
            f"{count} | {1e3 * med(step_wall):.1f} ({1e3 * med(step_cpu):.1f}) | {1e3 * porosity:.1f} "
            f"({1e3 * porosity_cpu:.1f}) | {1e3 * solve:.1f} ({1e3 * solve_cpu:.1f}) | "
            f"{med(iterations):.0f} | {1e3 * forces:.2f} ({1e3 * forces_cpu:.2f}) | {1e3 * med(dem):.1f}"
        )
