"""`sphere bench gpu`: the DEM step on a CUDA GPU (simulation.device = "cuda",
physics/device_steps.py) on the canonical scene of `sphere bench dem` (bench/dem.py), loose and
settled (the settled beds settled on the GPU itself, cached like the CPU's): particle-steps per
second in double precision, the bytes kept on the device per particle, and each kernel's share
of a step (from a second, profiled run that waits for each kernel: its total is longer than the
timed run's). A timing is `steps` steps on the device, from the first launch to the end of the
last kernel; bringing the state back to the host (what a run does for each output) is timed
apart, and the rate with one such copy per `steps` steps is given beside it: at 10^6 spheres the
copy costs as much as a few hundred steps. `walls` "moving" adds loose rows whose lid keeps a
normal stress and slides along x at a set velocity (MOVING_LID): the walls' own steps and the
exact sum of the particles' forces on them, on top of the same scene. `fluids` "navier-stokes"
adds loose rows in water, periodic across (without the side walls), on a Navier-Stokes grid of
cells about four diameters wide stepped every COUPLING_STEPS steps (NAVIER_STOKES): the drag and
its kick every step, the porosity and the momentum exchange on the device and the grid's fields
to and fro at each fluid step, the grid's step itself on the device too (physics/fluid/
device_navier_stokes.py) from the fluid module's hook on the host, whose whole time is shared out
beside the kernels' as "fluid step". `fluids` "darcy" adds loose rows in the same box (its walls
kept) filled with water on a Darcy grid of the same cells: the seepage force every step, the
porosity and mean particle velocity on the device and the pore pressure's step there too
(physics/fluid/device_pore_pressure.py) at each fluid step. Never part of the tests' timings.
"""

from __future__ import annotations

import math
import statistics
import time
from pathlib import Path

from ..config.load import parse_case
from ..io.json_text import json_text
from ..scene.builder import build_scene
from ..simulation import advance
from . import machine
from .dem import FIXED_LID, MOVING_LID, SPACING, canonical_case, on_device, settled_scene

# the canonical scene in water (`fluids`): cells about four diameters wide
COUPLING_STEPS = 10
IN_WATER = {
    "navier-stokes": """
[fluid]
model = "navier-stokes"
density = 1000.0
viscosity = 1.0e-3
grid = {{ cells = [{across}, {across}, {up}] }}
coupling = {{ steps = {steps} }}
""",
    "darcy": """
[fluid]
model = "darcy"
grid = {{ cells = [{across}, {across}, {up}] }}
coupling = {{ steps = {steps} }}
""",
}


def run_gpu_benchmark(
    sizes=(100_000, 1_000_000, 10_000_000),
    steps: int = 200,
    repeats: int = 3,
    states=("loose", "settled"),
    out_dir: Path = Path("bench-results"),
    log=print,
    walls=("fixed",),
    fluids=("none",),
) -> dict:
    out_dir.mkdir(parents=True, exist_ok=True)
    results = {"machine": machine(), "steps": steps, "repeats": repeats, "rows": []}
    rows = [(state, "fixed", "none") for state in states if "fixed" in walls and "none" in fluids]
    rows += [("loose", "moving", "none")] if "moving" in walls else []
    rows += [("loose", "fixed", fluid) for fluid in IN_WATER if fluid in fluids]
    for n in sizes:
        for state, lid, fluid in rows:
            if state == "loose":
                text = canonical_case(n)
                if lid == "moving":
                    text = text.replace(FIXED_LID, MOVING_LID)
                if fluid != "none":
                    text = _in_water(text, n, fluid)
                scene = build_scene(parse_case(on_device(text, "cuda")))
            else:
                scene = settled_scene(n, log, device="cuda")
            device = scene.step.compiled
            advance(scene, 5, sync=False)  # compiles the kernels (cached after a first run), uploads
            times, copies = _time_on_device(scene, steps, repeats)
            device.timings = {}
            hooks = scene.step.after_step
            scene.step.after_step = tuple(_timed(module, hook, device.timings) for module, hook in hooks)
            advance(scene, steps)
            scene.step.after_step = hooks
            profiled, device.timings = device.timings, None
            total = sum(profiled.values())
            median, copy = statistics.median(times), statistics.median(copies)
            row = {
                "n": n,
                "state": state,
                "walls": lid,
                "fluid": fluid,
                "gpu": device.device_name,
                "steps": steps,
                "seconds": median,
                "all_seconds": times,
                "particle_steps_per_second": n * steps / median,
                "best_particle_steps_per_second": n * steps / min(times),
                "to_host_seconds": copy,
                "particle_steps_per_second_with_output": n * steps / (median + copy),
                "device_bytes_per_particle": device.device_bytes() / n,
                "neighbor_rebuilds": scene.state.neighbors.builds,
                "kernel_shares": {name: seconds / total for name, seconds in sorted(profiled.items())},
            }
            results["rows"].append(row)
            shares = ", ".join(f"{name} {share:.0%}" for name, share in row["kernel_shares"].items())
            log(
                f"N = {n:>8} {state:>7} {lid:>6} walls{'' if fluid == 'none' else ', ' + fluid} "
                f"{row['particle_steps_per_second'] / 1e6:8.1f} M particle-steps/s "
                f"(median of {repeats} x {steps} steps; "
                f"best {row['best_particle_steps_per_second'] / 1e6:.1f} M; "
                f"{row['device_bytes_per_particle']:.0f} B/particle on the GPU); state to the host in "
                f"{copy * 1e3:.1f} ms (once per {steps} steps: "
                f"{row['particle_steps_per_second_with_output'] / 1e6:.1f} M particle-steps/s); {shares}"
            )
    (out_dir / "bench-gpu.json").write_text(json_text(results))
    log(f"results written to {out_dir / 'bench-gpu.json'}")
    return results


def _timed(module, hook, timings: dict) -> tuple:
    """(module, its after_step hook timed into timings as "<module> step"): a fluid's own step
    and the stages, called from the host between the device's runs of steps (a Navier-Stokes
    grid's step launches its own kernels on the device)."""
    name = f"{module.name} step"

    def timed_hook(state) -> None:
        started = time.perf_counter()
        hook(state)
        timings[name] = timings.get(name, 0.0) + time.perf_counter() - started

    return module, timed_hook


def _in_water(text: str, n: int, model: str) -> str:
    """The canonical scene of n spheres (its case text) in water of the fluid `model` (IN_WATER),
    on cells about four diameters wide; for Navier-Stokes periodic across, as its grid requires,
    without the side walls."""
    if model == "navier-stokes":
        for face in ("x-", "x+", "y-", "y+"):
            text = text.replace(f'[[walls]]\nface = "{face}"\n', "")
        text = text.replace("[particles]", "periodic = [true, true, false]\n[particles]")
    side = math.ceil(n ** (1.0 / 3.0))  # lattice sites across (bench/dem.py canonical_case)
    across = max(1, round(side * SPACING / 4.0))
    return text + IN_WATER[model].format(across=across, up=2 * across, steps=COUPLING_STEPS)


def _time_on_device(scene, steps: int, repeats: int) -> tuple[list[float], list[float]]:
    """(seconds for `steps` steps on the device, seconds to bring the state back) per repeat."""
    device = scene.step.compiled
    stepping, copying = [], []
    for _ in range(repeats):
        started = time.perf_counter()
        advance(scene, steps, sync=False)
        device.cuda.synchronize()
        stepped = time.perf_counter()
        device.to_host(scene.state)
        stepping.append(stepped - started)
        copying.append(time.perf_counter() - stepped)
    return stepping, copying
