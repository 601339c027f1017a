"""`sphere bench dem`: particle-steps per second on the canonical scene (never part of the tests).

Canonical scene: N monodisperse spheres, R = 1 mm, rho = 2500 kg/m^3,
linear contact k_n = 1e5 N/m, k_t = 2/7 k_n, e = 0.5, mu = 0.5, six fixed walls, gravity,
dt = 4e-6 s (0.65 x the stability limit of one contact, 6.5 x the bound for spheres held by 12
contacts at once: physics/contact.py; the bed settles at coordination ~6, so the case says
stability = "contact"); once from a loose lattice (spacing 1.2 d) and once from the settled bed.
The settled bed is made once by letting the same particles, placed on a denser lattice
(SETTLE_SPACING), fall for SETTLE_TIME of simulated time with the canonical contact law and dt;
it is cached under the user cache directory, keyed by the text of that case (an interrupted
settling resumes from its last checkpoint).
The fixed cost of a step, the intercept of step time against N over loose scenes of 10 to
10 000 spheres, is reported after the rows. A last row times a sparse scene: one sphere of 0.5 mm in a
1 m cube falling onto its floor, SPARSE_STEPS steps (the search's memory and time follow the
particle count, not the box volume over the particle size: physics/neighbors.py).
Compile (or cache-load) time is measured apart from run time; each row reports the median of
`repeats` runs of `steps` steps, and the best of them (on a machine shared with other jobs, many
short runs and their best approach what an idle machine gives).
"""

from __future__ import annotations

import hashlib
import math
import os
import statistics
import time
from pathlib import Path

import numba
import numpy as np

from ..config.load import parse_case
from ..io.checkpoint import FORMAT, newest_valid_checkpoint
from ..io.json_text import json_text
from ..runtime import shared_cores_note
from ..scene.builder import build_scene
from ..simulation import advance
from . import Stopwatch, machine

RADIUS = 1e-3
SPACING = 1.2
# The settled bed starts from a denser lattice (less to fall) and comes to rest within
# SETTLE_TIME of simulated time; same box, particles, contact law and dt as the canonical scene.
SETTLE_SPACING = 1.05
SETTLE_TIME = 0.15  # s
SETTLE_CHECKPOINTS = 0.01  # s of simulated time between checkpoints while settling
SPARSE_STEPS = 1000
FIXED_COST_SIZES = (10, 30, 100, 300, 1000, 3000, 10_000)  # N of the fixed-cost fit
SPARSE_CASE = """
title = "sparse benchmark scene: one small sphere in a 1 m cube"
[simulation]
duration = 1.0
dt = 5.0e-6
[domain]
upper = [1.0, 1.0, 1.0]
[particles]
count = 1
density = 2500.0
radius = 0.0005
[contact]
model = "linear"
normal_stiffness = 1.0e4
[[walls]]
face = "z-"
"""


def canonical_case(
    n: int, duration: float = 1.0, checkpoint_every: float | None = None, spacing: float = SPACING
) -> str:
    """The canonical scene as case-file text: a box about N^(1/3) lattice sites wide and twice
    as tall, so the loose lattice fills its lower half."""
    d = 2.0 * RADIUS
    side = math.ceil(n ** (1.0 / 3.0))
    width = side * SPACING * d + d
    layers = math.ceil(n / side**2)
    height = max(2.0 * width, (layers + 1) * SPACING * d + d)
    walls = "\n".join(f'[[walls]]\nface = "{f}"' for f in ("x-", "x+", "y-", "y+", "z-", "z+"))
    return f"""
title = "canonical benchmark scene, N = {n}"
[simulation]
duration = {duration!r}
dt = 4.0e-6
stability = "contact"
[domain]
upper = [{width!r}, {width!r}, {height!r}]
[particles]
count = {n}
density = 2500.0
radius = {{ distribution = "fixed", value = {RADIUS!r} }}
placement = {{ method = "lattice", spacing = {spacing!r}, jitter = 1.0 }}
[contact]
model = "linear"
normal_stiffness = 1.0e5
tangential_stiffness = {2.0 / 7.0 * 1.0e5!r}
restitution = 0.5
friction = 0.5
{walls}
[output.frames]
every_time = {duration!r}
[output.checkpoints]
every_time = {checkpoint_every or duration!r}
keep = 1
"""


def on_device(text: str, device: str) -> str:
    """A case's text with simulation.device set (the CPU's text unchanged)."""
    return (
        text if device == "cpu" else text.replace("[simulation]\n", f'[simulation]\ndevice = "{device}"\n', 1)
    )


# the canonical scene's lid, and the same stress-controlled and sliding (`sphere bench gpu` and
# `sphere bench ranks` with --walls moving)
FIXED_LID = '[[walls]]\nface = "z+"'
MOVING_LID = FIXED_LID + '\nmode = "stress"\nstress = 1000.0\nshear_axis = "x"\nshear_velocity = 0.01'
PRESSED_SIDES = 200.0  # [Pa] ~ K0 phi rho g h/2 of the settled bed (0.5 x 0.6 x 2500 x 9.81 x 0.027)


def settled_cache_dir(n: int, device: str = "cpu") -> Path:
    """Where the settled bed of N spheres is kept: the user cache, keyed by the text of the
    settling case (N, every parameter and the device that settles it) and the checkpoint format
    (a cache another format wrote is settled again). A change of the code's defaults is not seen:
    delete the folder to settle again."""
    text = on_device(canonical_case(n, SETTLE_TIME, SETTLE_CHECKPOINTS, SETTLE_SPACING), device)
    text += f"# checkpoint format {FORMAT}\n"
    digest = hashlib.sha256(text.encode()).hexdigest()
    base = Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache"))
    return base / "sphere" / "bench" / f"settled-{n}-{digest[:12]}"


def settled_scene(n: int, log, device: str = "cpu", lid: str = "fixed"):
    """The canonical scene from its settled bed, settled on `device` (the GPU settles the beds of
    sphere bench gpu, too large for the CPU); with `lid` "moving", its lid stress-controlled and
    sliding (MOVING_LID) and put down onto the bed, touching its highest sphere, and its x+ and
    y+ walls keeping PRESSED_SIDES (about the bed's lateral stress half-way up): each step then
    moves the walls and sums the pushes of the particles along two sides and under the lid."""
    from .. import api

    run_dir = settled_cache_dir(n, device)
    ck = newest_valid_checkpoint(run_dir / "checkpoints") if run_dir.is_dir() else None
    if ck is None or ck.step * ck.dt < SETTLE_TIME * (1 - 1e-6):
        log(f"settling N = {n} for {SETTLE_TIME} s of simulated time (cached in {run_dir}) ...")
        if ck is None:
            run_dir.parent.mkdir(parents=True, exist_ok=True)
            case_path = run_dir.parent / f"canonical-{n}.toml"
            case_path.write_text(
                on_device(canonical_case(n, SETTLE_TIME, SETTLE_CHECKPOINTS, SETTLE_SPACING), device)
            )
            api.run(case_path, run_dir, overwrite=True)
        else:
            api.resume(run_dir)
        ck = newest_valid_checkpoint(run_dir / "checkpoints")
    text = canonical_case(n)
    if lid == "moving":
        text = text.replace(FIXED_LID, MOVING_LID)
        for face in ("x+", "y+"):
            side = f'[[walls]]\nface = "{face}"\n'
            text = text.replace(side, f'{side}mode = "stress"\nstress = {PRESSED_SIDES}\n')
    scene = build_scene(parse_case(on_device(text, device)), restart=ck)
    if lid == "moving":
        p, w = scene.state.particles, scene.state.walls
        w.coord[w.faces.index("z+")] = float(np.max(p.pos[:, 2] + p.radius))
    return scene


def time_steps(scene, steps: int, repeats: int) -> list[float]:
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        advance(scene, steps)
        times.append(time.perf_counter() - t0)
    return times


# the hooks of a step whose calls time_parts times, in the step's order
PART_HOOKS = ("kick_drift", "prepare", "forces", "kick", "finish_step", "after_step")


def time_parts(scene, steps: int) -> dict[str, float]:
    """Nanoseconds a particle-step in each hook of `steps` steps ("Motion.kick_drift",
    "NeighborSearch.prepare" with its list builds, "PairContactForces.forces", ...), and in the
    whole step so taken ("step"). Each hook is timed where the step calls it, so the steps run
    through the hooks one at a time: the same kernels as the compiled loop
    (physics/compiled_steps.py) with the interpreter between them, which the whole step counts
    and the parts do not."""
    hooks = [(bound.__self__, name) for name in PART_HOOKS for bound in getattr(scene.step, name)]
    watches = {f"{type(module).__name__}.{name}": Stopwatch(module, name) for module, name in hooks}
    scene.order_modules()
    try:
        start = time.perf_counter()
        advance(scene, steps)
        whole = time.perf_counter() - start
    finally:
        for watch in watches.values():
            watch.restore()
        scene.order_modules()
    per = 1e9 / (steps * scene.state.particles.count)
    return {**{key: sum(watch.seconds) * per for key, watch in watches.items()}, "step": whole * per}


def bytes_per_particle(scene) -> float:
    """Every array the time loop keeps per particle, scratch included, divided by N."""
    state = scene.state
    p = state.particles
    arrays = [getattr(p, name) for name in p.PROGNOSTIC] + [p.vel_pred, p.angvel_pred]
    nl = state.neighbors
    contact = scene.contact
    arrays += [nl.nbr, nl.nbr_count, nl.hist, nl.ref_pos, nl.rev, nl.rev_count, contact.slots]
    arrays += [contact.blocks, contact.block_ids, contact.block_rows]
    search = scene.neighbors
    arrays += [nl.start, search.spare_nbr, search.spare_count, search.spare_start, search.spare_hist]
    arrays += [search.cell_of, search.order, search.cell_start, search.cell_key]
    if state.walls is not None:
        arrays.append(state.walls.hist)
        arrays += scene.walls.scratch()
    return sum(a.nbytes for a in arrays) / p.count


def run_benchmark(
    sizes=(10_000, 100_000),
    threads=(1, 2),
    steps: int = 200,
    repeats: int = 3,
    states=("loose", "settled"),
    out_dir: Path = Path("bench-results"),
    log=print,
    fixed_cost_sizes=FIXED_COST_SIZES,
) -> dict:
    out_dir.mkdir(parents=True, exist_ok=True)
    max_threads = numba.config.NUMBA_NUM_THREADS
    results = {"machine": machine(), "steps": steps, "repeats": repeats, "rows": []}
    # sampled before any kernel runs, so that no thread of the benchmark counts as busy
    note = shared_cores_note(min(max(threads, default=1), max_threads))
    results["shared_cores_note"] = note
    if note is not None:
        log(f"warning: {note}")
    t0 = time.perf_counter()
    warm = build_scene(parse_case(canonical_case(64)))
    advance(warm, 2)  # two: the compiled steps too (physics/compiled_steps.py)
    results["first_call_seconds"] = time.perf_counter() - t0
    log(f"compile / cache load of the kernels: {results['first_call_seconds']:.2f} s")
    for n in sizes:
        for state_name in states:
            if state_name == "loose":
                scene = build_scene(parse_case(canonical_case(n)))
            else:
                scene = settled_scene(n, log)
            contacts = _mean_contacts(scene)
            for t in threads:
                if t > max_threads:
                    continue
                numba.set_num_threads(t)
                advance(scene, 5)
                times = time_steps(scene, steps, repeats)
                median = statistics.median(times)
                row = {
                    "n": n,
                    "state": state_name,
                    "threads": t,
                    "steps": steps,
                    "seconds": median,
                    "all_seconds": times,
                    "particle_steps_per_second": n * steps / median,
                    # on a shared machine the fastest timing is the one least disturbed by others
                    "best_particle_steps_per_second": n * steps / min(times),
                    "contacts_per_particle": contacts,
                    "neighbor_rebuilds": scene.state.neighbors.builds,
                    "bytes_per_particle": bytes_per_particle(scene),
                    "parts_ns_per_particle_step": time_parts(scene, steps),
                }
                results["rows"].append(row)
                log(
                    f"N = {n:>7} {state_name:>7}  threads = {t}  "
                    f"{row['particle_steps_per_second'] / 1e6:6.2f} M particle-steps/s  "
                    f"(median of {repeats} x {steps} steps; "
                    f"best {row['best_particle_steps_per_second'] / 1e6:.2f} M; "
                    f"{contacts:.2f} contacts/particle, "
                    f"{row['bytes_per_particle']:.0f} B/particle)"
                )
                parts = dict(row["parts_ns_per_particle_step"])
                whole = parts.pop("step")
                compiled = 1e9 / row["particle_steps_per_second"]
                log(
                    "    ns a particle-step through the hooks: "
                    + ", ".join(f"{name} {ns:.1f}" for name, ns in parts.items())
                    + f"; the step {whole:.1f} (in the compiled loop {compiled:.1f})"
                )
            numba.set_num_threads(max_threads)
    _speedups(results, log)
    if fixed_cost_sizes:
        results["fixed_cost"] = _fixed_cost(fixed_cost_sizes, log)
    results["sparse"] = _sparse_row(log)
    (out_dir / "bench.json").write_text(json_text(results))
    log(f"results written to {out_dir / 'bench.json'}")
    return results


def _fixed_cost(sizes, log) -> dict:
    """The cost of a step that does not grow with N: the intercept of a straight line through
    the step times of loose canonical scenes of `sizes` spheres (one thread; the best
    of 7 timings of about 2e5 particle-steps each, so that a busy machine's slices fall out)."""
    threads = numba.get_num_threads()
    numba.set_num_threads(1)
    seconds = []
    for n in sizes:
        scene = build_scene(parse_case(canonical_case(n)))
        advance(scene, 20)
        seconds.append(min(time_steps(scene, max(20, 200_000 // n), 7)) / max(20, 200_000 // n))
    numba.set_num_threads(threads)
    slope, intercept = np.polyfit(sizes, seconds, 1)
    log(
        f"fixed cost of a step (intercept over N = {sizes[0]}..{sizes[-1]}, "
        f"loose scenes, one thread): {intercept * 1e6:.1f} us, then {slope * 1e9:.1f} ns per particle"
    )
    return {"sizes": list(sizes), "step_seconds": seconds, "intercept_seconds": float(intercept)}


def _sparse_row(log) -> dict:
    scene = build_scene(parse_case(SPARSE_CASE))
    search = scene.neighbors
    cells = search.cell_start.nbytes + search.cell_key.nbytes
    seconds = min(time_steps(scene, SPARSE_STEPS, 3))
    log(
        f"sparse scene (1 sphere of 0.5 mm in a 1 m cube, {search.ncell.prod():.3g} cells of the search): "
        f"{SPARSE_STEPS} steps in {seconds:.3f} s, {cells} B of cell index"
    )
    return {"steps": SPARSE_STEPS, "seconds": seconds, "cell_index_bytes": cells}


def _mean_contacts(scene) -> float:
    from ..physics.observe.energy import observables

    obs = observables(scene)
    return 2.0 * obs["contacts"] / scene.state.particles.count


def _speedups(results: dict, log) -> None:
    rows = results["rows"]
    for row in rows:
        if row["threads"] == 1:
            continue
        base = [r for r in rows if r["n"] == row["n"] and r["state"] == row["state"] and r["threads"] == 1]
        if base:
            row["speedup"] = row["particle_steps_per_second"] / base[0]["particle_steps_per_second"]
            log(
                f"N = {row['n']:>7} {row['state']:>7}  {row['threads']} threads: "
                f"{row['speedup']:.2f} x one thread"
            )
    policy = results["machine"]["omp_wait_policy"]
    if policy == "PASSIVE" and any(row["threads"] > 1 for row in rows):
        log(
            "    (OMP_WAIT_POLICY=PASSIVE: the threads sleep between parallel regions and each region "
            "wakes them, which lowers the figures of several threads most on small scenes; a run on "
            "cores of its own keeps the default)"
        )
