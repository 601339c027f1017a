"""Many dry DEM steps in one compiled call (physics/compiled_steps.py, kernels/steps.py): bitwise
the step-by-step loop, on the scenes it applies to, and left out where it does not apply."""

from __future__ import annotations

from pathlib import Path

import h5py
import numba
import numpy as np
import pytest
from numba.core import types

from sphere_cli import api
from sphere_cli.bench.dem import canonical_case
from sphere_cli.config.load import load_case, parse_case
from sphere_cli.io.checkpoint import list_checkpoints, read_checkpoint
from sphere_cli.kernels import contact as kernels_contact
from sphere_cli.kernels import motion as kernels_motion
from sphere_cli.kernels import steps as kernels_steps
from sphere_cli.kernels import walls as kernels_walls
from sphere_cli.kernels.exact_sum import WORDS
from sphere_cli.kernels.fluid import drag as kernels_drag
from sphere_cli.kernels.fluid import porosity as kernels_porosity
from sphere_cli.kernels.fluid import profile_forces as kernels_profile
from sphere_cli.kernels.fluid.drag import drag_steps, drag_steps_serial
from sphere_cli.kernels.fluid.profile_forces import vans1d_steps, vans1d_steps_serial
from sphere_cli.kernels.observe import energy_budget as kernels_budget
from sphere_cli.kernels.steps import dem_steps, dem_steps_serial
from sphere_cli.physics import contact as contact_module
from sphere_cli.physics import motion as motion_module
from sphere_cli.scene.builder import build_scene
from sphere_cli.simulation import advance

CONFIGS = Path(__file__).parents[2] / "configs"
STEPS = 1500


def _state(scene) -> dict:
    p, nl, w = scene.state.particles, scene.state.neighbors, scene.state.walls
    arrays = {name: getattr(p, name) for name in ("pos", "vel", "angvel", "force", "torque")}
    arrays["springs"] = nl.hist[: nl.start[-1]]
    arrays["nbr"] = nl.nbr
    if w is not None:
        arrays["wall springs"] = w.hist
    if scene.state.fluid is not None and hasattr(scene.state.fluid, "column"):  # 1D VANS
        arrays["fluid velocity"] = scene.state.fluid.column.u
    elif scene.state.fluid is not None:  # Navier-Stokes
        drag = scene.fluid.drag
        arrays.update(v=scene.fluid.fs.v, p=scene.fluid.fs.p, impulse=drag.impulse, f_drag=drag.f_drag)
        arrays["self-induced"] = drag.disturbance
    return arrays


def _fluidized(averaging: str, floor: float | None = None, lid: bool = False):
    """configs/fluidized-bed.toml (192 beads, 4 of its 12 layers fixed, water forced up through
    a 1 x 1 x 8 Navier-Stokes grid, a fluid step every 5 DEM steps), the free beads thrown
    sideways at 0.2 m/s across the periodic faces, so that the list goes stale every ~150
    steps; the drag per particle less its self-induced velocity, or cell-averaged. `lid`: under
    a top wall pressed down by 2 kPa, which the grid follows (its cells stretched at every
    fluid step), and which reaches the free beads in ~1 000 steps."""
    text = (CONFIGS / "fluidized-bed.toml").read_text()
    text = text.replace('law = "gidaspow"\n', f'law = "gidaspow"\naveraging = "{averaging}"\n')
    if floor is not None:
        text = text.replace('law = "gidaspow"\n', f'law = "gidaspow"\nporosity_floor = {floor}\n')
    text = text.replace("[particles]\n", "[particles]\nvelocity = [0.2, 0.1, 0.0]\n")
    assert text.count("averaging") == 1 and "0.2, 0.1" in text
    if lid:
        for old, new in (
            ("[fluid]\n", '[[walls]]\nface = "z+"\nmode = "stress"\nstress = 2000.0\n\n[fluid]\n'),
            ("grid = { cells = [1, 1, 8] }", "grid = { cells = [1, 1, 4], follow_top_wall = true }"),
            ("upper = [0.004, 0.004, 0.032]", "upper = [0.004, 0.004, 0.016]"),
        ):
            text = text.replace(old, new)
        assert "follow_top_wall" in text and 'mode = "stress"' in text and "0.016]" in text
    return parse_case(text)


def _case(name: str):
    """hertz-mixture: a pour onto six walls (Hertz-Mindlin, rolling resistance, two materials);
    bedload: 1000 beads under a 1D VANS flow (its force on the particles in the loop, its
    coupling every 1e-3 s between calls, periodic in x and y);
    canonical: 400 spheres packed close between six walls (linear law, friction), falling into
    contact; periodic: the same spheres periodic in x and y over a floor, thrown sideways at
    0.5 m/s, so that they cross the periodic faces and make the list stale often."""
    if name in ("hertz-mixture", "bedload"):
        return load_case(CONFIGS / f"{name}.toml")
    text = canonical_case(400, spacing=1.05)
    if name == "periodic":
        for face in ("x-", "x+", "y-", "y+"):
            text = text.replace(f'[[walls]]\nface = "{face}"\n', "")
        text = text.replace("[domain]\n", "[domain]\nperiodic = [true, true, false]\n")
        text = text.replace("[particles]\n", "[particles]\nvelocity = [0.5, 0.3, 0.0]\n")
        assert text.count("[[walls]]") == 2 and "periodic" in text and "0.5, 0.3" in text
    return parse_case(text)


@pytest.mark.parametrize("name", ["hertz-mixture", "canonical", "periodic", "bedload"])
@pytest.mark.parametrize("threads", [1, 2])
def test_compiled_steps_are_the_step_by_step_loop_bitwise(name, threads):
    numba.set_num_threads(threads)
    try:
        compiled, stepwise = build_scene(_case(name)), build_scene(_case(name))
        assert compiled.step.compiled is not None
        stepwise.step.compiled = None
        for scene in (compiled, stepwise):
            advance(scene, STEPS - 7)  # the end falls between list builds, not on one
            advance(scene, 7)
        # the runs rebuilt the list several times: the compiled loop stopped at stale lists
        assert compiled.state.neighbors.builds == stepwise.state.neighbors.builds >= 2
        assert compiled.state.clock.step == stepwise.state.clock.step == STEPS
        a, b = _state(compiled), _state(stepwise)
        assert np.count_nonzero(a["springs"].any(axis=1)) > 0  # contacts with friction
        for key in a:
            assert np.array_equal(a[key], b[key]), key
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)


def _direct_shear():
    """configs/direct-shear.toml with its stages shortened: deposit (walls fixed, a kinetic-energy
    stop tested every check_every steps), consolidate (the rough top wall approaches, then
    keeps 1 kPa: stress-controlled) and shear (it also moves sideways); glued spheres on both
    walls; the energy budget observed (its hooks in the loop). About 8 000 steps."""
    text = (CONFIGS / "direct-shear.toml").read_text()
    for old, new in (("duration = 0.15", "duration = 0.012"), ("min_time = 0.06", "min_time = 0.006")):
        text = text.replace(old, new)
    text = text.replace("duration = 0.05", "duration = 0.008").replace("duration = 0.08", "duration = 0.008")
    assert text.count("\nquantities = [") == 1
    text = text.replace("\nquantities = [", '\nquantities = ["energy_budget", ')
    return parse_case(text)


def _walls_driven():
    """64 spheres at rest without gravity between six walls: the top wall comes down at 2 m/s,
    the x+ wall is pushed in by a stress of 200 +- 100 Pa at 100 Hz (its target depends on the
    time). No particle moves before a wall reaches it, so only the walls' own motion makes the
    near-wall list again. 2 500 steps."""
    text = canonical_case(64, spacing=1.05).replace("[domain]\n", "[domain]\ngravity = [0.0, 0.0, 0.0]\n")
    text = text.replace('face = "z+"', 'face = "z+"\nmode = "velocity"\nvelocity = 2.0')
    text = text.replace(
        'face = "x+"',
        'face = "x+"\nmode = "stress"\nstress = 200.0\nstress_amplitude = 100.0\nfrequency = 100.0',
    )
    return parse_case(text)


def _sheared_in_a_fluid():
    """The 400 spheres of _case("periodic") (periodic in x and y, thrown sideways over a floor)
    under a 1D VANS flow (its force on them every step, the column solved every 10 steps), a
    lid keeping 500 Pa and sliding at 5 cm/s along x above them, and the energy budget. 2 500
    steps."""
    text = canonical_case(400, spacing=1.05)
    for face in ("x-", "x+", "y-", "y+"):
        text = text.replace(f'[[walls]]\nface = "{face}"\n', "")
    text = text.replace("[domain]\n", "[domain]\nperiodic = [true, true, false]\n")
    text = text.replace("[particles]\n", "[particles]\nvelocity = [0.5, 0.3, 0.0]\n")
    lid = 'face = "z+"\nmode = "stress"\nstress = 500.0\nshear_axis = "x"\nshear_velocity = 0.05\n'
    text = text.replace('face = "z+"\n', lid)
    text += (
        '[fluid]\nmodel = "vans1d"\nsurface = 0.03\ncells = 30\ncoupling = { steps = 10 }\nflow = { kind = '
        '"solved", mixing_length = "prandtl", pressure_gradient = -2000.0, initial = "rest" }\n'
        '[output.observables]\nquantities = ["energy_budget"]\n'
    )
    return parse_case(text)


# the fluid's case on one thread only: its loop on two is the same code with the parallel
# kernels the other cases compare (and 15 s more of compiling in make test)
@pytest.mark.parametrize(
    "name, threads",
    [
        ("direct-shear", 1),
        ("direct-shear", 2),
        ("walls-driven", 1),
        ("walls-driven", 2),
        ("lid-over-a-fluid", 1),
    ],
)
def test_moving_walls_and_stages_in_the_compiled_loop_are_the_step_by_step_loop_bitwise(name, threads):
    """The walls' motion runs inside the compiled loop (their kick-drift before the particles',
    their kick before the particles', at the step's time), which ends where a stage may end
    (simulation.advance) and where a wall has moved half the skin from where the near-wall list
    was made; so does the energy budget's (what it keeps before the contacts, its booking after
    the kick), each particle's shares bitwise the hooks'."""
    make = {
        "direct-shear": _direct_shear,
        "walls-driven": _walls_driven,
        "lid-over-a-fluid": _sheared_in_a_fluid,
    }[name]
    numba.set_num_threads(threads)
    try:
        compiled, stepwise = build_scene(make()), build_scene(make())
        assert compiled.step.compiled is not None and compiled.step.compiled.moving
        assert (compiled.step.compiled.budget is not None) == (name != "walls-driven")
        assert (compiled.step.compiled.fluid is not None) == (name == "lid-over-a-fluid")
        stepwise.step.compiled = None
        for scene in (compiled, stepwise):
            if name.startswith("direct-shear"):
                while not scene.finished:
                    advance(scene, 10**9)
            else:
                advance(scene, 2500)
        assert compiled.state.clock.step == stepwise.state.clock.step >= 2500
        assert compiled.state.neighbors.builds == stepwise.state.neighbors.builds
        a, b = _state(compiled), _state(stepwise)
        w, v = compiled.state.walls, stepwise.state.walls
        for wall in "coord", "vel", "acc", "shift", "force", "area":
            a[f"wall {wall}"], b[f"wall {wall}"] = getattr(w, wall), getattr(v, wall)
        if compiled.budget is not None:
            a["booked"], b["booked"] = compiled.budget.booked, stepwise.budget.booked
            assert np.count_nonzero(a["booked"]) > 0
        if name.startswith("direct-shear"):
            assert abs(w.shift[1, 0]) > 1e-4  # the top wall has sheared the bed
        elif name == "lid-over-a-fluid":
            assert np.count_nonzero(a["fluid velocity"]) > 0 and w.shift[1, 0] > 0.0  # the flow, the lid
        else:  # both walls have reached the spheres
            assert np.count_nonzero(np.abs(w.force[[1, 5]]).max(axis=1)) == 2, w.force
        for key in a:
            assert np.array_equal(a[key], b[key]), key
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)


def test_each_chunk_of_the_one_region_step_takes_the_walls_of_its_own_particles():
    """PlaneWallForces.by_chunks cuts the near-wall list at the pair sweep's chunks, so that
    kernels/steps.py chunk_steps_end's chunk c takes the walls of its own particles only (another
    chunk's particles are kicked and drifted by their own thread meanwhile), every listed
    particle once; the rest of wall_forces's arguments stay as they are."""
    from sphere_cli.physics.walls import PlaneWallForces

    near = np.array([0, 3, 4, 9, 10, 11, 17, 0, 0], dtype=np.int64)  # 7 listed, then unused room
    arguments = list(range(kernels_walls.PIECES + 4))
    arguments[kernels_walls.NEAR] = near
    arguments[kernels_walls.PIECES] = np.array([0, 5, 7], dtype=np.int64)  # two threads' cut
    bounds = np.array([0, 4, 10, 20], dtype=np.int64)
    chunked = PlaneWallForces.by_chunks(tuple(arguments), bounds)
    cut = chunked[kernels_walls.PIECES]
    assert cut.tolist() == [0, 2, 4, 7]
    for c in range(3):
        assert np.all((near[cut[c] : cut[c + 1]] >= bounds[c]) & (near[cut[c] : cut[c + 1]] < bounds[c + 1]))
    others = [i for i in range(len(arguments)) if i != kernels_walls.PIECES]
    assert all(chunked[i] is arguments[i] for i in others)


def test_the_walls_totals_from_the_near_wall_list_are_the_dense_sums_bitwise():
    """The compiled loop sums the particles' pushes on moving walls over the near-wall list
    (listed_wall_totals), the hooks over every particle (wall_totals): the same bits, with the
    forces spread over 16 orders of magnitude (the order of a sum shows in its bits) on the
    listed particles, every fifth of them not touching, the others zero as wall_forces leaves
    them; three of four walls recorded, 30 glued spheres."""
    rng = np.random.default_rng(3)
    n, walls = 1000, 4
    listed = np.sort(rng.choice(n, 300, replace=False))
    pforce = np.zeros((n, walls, 3))
    shape = (listed.size, walls, 3)
    pforce[listed] = rng.standard_normal(shape) * 10.0 ** rng.integers(-8, 9, shape)
    pforce[listed[2::5]] = 0.0
    record = np.array([1, 0, 1, 1], dtype=np.uint8)
    glued = (rng.choice(n, 30, replace=False), rng.integers(0, walls, 30))
    rest = (rng.standard_normal((n, 3)), rng.random(n), np.array([0.0, 0.0, -9.81]), rng.random((walls, 3)))
    dense, sparse = np.zeros((walls, 3)), np.zeros((walls, 3))
    sums = np.zeros((walls, 3, WORDS), dtype=np.int64)
    kernels_walls.wall_totals(pforce, record, sums, *glued, *rest, dense)
    kernels_walls.listed_wall_totals(listed, pforce, record, sums, *glued, *rest, sparse)
    assert dense.tobytes() == sparse.tobytes()
    assert np.count_nonzero(dense[[0, 2, 3]] != rest[3][[0, 2, 3]]) == 9


@pytest.mark.parametrize(
    ("averaging", "threads", "lid"),
    [("particle", 1, False), ("particle", 2, False), ("cell", 1, False), ("particle", 1, True)],
    ids=["particle-1", "particle-2", "cell-1", "particle-1-lid"],
)
def test_the_navier_stokes_drag_in_the_compiled_loop_is_the_step_by_step_loop_bitwise(
    averaging, threads, lid
):
    """The Navier-Stokes drag's loop (kernels/fluid/drag.py drag_steps): the particles binned
    into the fluid's cells, their drag, the sums of the cells' drag coefficients (for the
    self-induced velocity, with the drag per particle) and the drag's exact kick in place of
    the particles' kick; the fluid's steps between the calls. Under a stress-controlled lid,
    which the grid follows, the lid's motion too, kicked from the beads' pushes once it reaches
    them."""
    numba.set_num_threads(threads)
    try:
        case = _fluidized(averaging, lid=lid)
        compiled, stepwise = build_scene(case), build_scene(case)
        assert compiled.step.compiled is not None and compiled.step.compiled.extra is compiled.fluid
        assert compiled.step.compiled.moving == lid
        assert compiled.fluid.drag.corrected == (averaging == "particle")
        stepwise.step.compiled = None
        steps = 2203 if lid else 1003  # not coupling steps (every 5th): the calls end between them
        for scene in (compiled, stepwise):
            advance(scene, steps)
            advance(scene, 8)
        assert compiled.state.neighbors.builds == stepwise.state.neighbors.builds >= 4
        assert compiled.state.clock.step == stepwise.state.clock.step == steps + 8
        a, b = _state(compiled), _state(stepwise)
        assert np.count_nonzero(a["impulse"]) > 0 and np.count_nonzero(a["self-induced"]) == (
            a["self-induced"].size if averaging == "particle" else 0
        )
        if lid:
            walls = (compiled.state.walls, stepwise.state.walls)
            assert walls[0].force[0, 2] > 0.0  # the lid on the beads
            for name in ("coord", "vel", "force"):
                assert np.array_equal(getattr(walls[0], name), getattr(walls[1], name)), name
            assert compiled.fluid.fs.height == stepwise.fluid.fs.height < 0.0125
        for key in a:
            assert np.array_equal(a[key], b[key]), key
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)


def test_the_navier_stokes_twins_on_one_thread_are_the_parallel_kernels_on_two_bitwise():
    """On one thread the drag's loop and hooks run the serial twins of the binning, the drag and
    its kick (kernels/serial.py); on two the parallel kernels: the same bits."""
    runs = {}
    try:
        for threads in (2, 1):
            numba.set_num_threads(threads)
            scene = build_scene(_fluidized("particle"))
            advance(scene, 1011)
            assert scene.state.neighbors.builds >= 4
            runs[threads] = _state(scene)
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    assert drag_steps_serial.overloads and drag_steps.overloads
    for key in runs[1]:
        assert np.array_equal(runs[1][key], runs[2][key]), key


def test_the_compiled_loop_warns_of_the_porosity_floor_at_the_step_the_hooks_do():
    """A porosity under fluid.drag.porosity_floor set between calls (the fluid's next step
    measures it again): the loop returns after the first step that finds particles under it,
    and the warning names that step and count, as the hooks' does; once a run."""
    found = []
    for compiled in (True, False):
        scene = build_scene(_fluidized("particle"))
        if not compiled:
            scene.step.compiled = None
        advance(scene, 7)
        scene.fluid.fs.porosity[...] = 0.05
        with pytest.warns(RuntimeWarning, match="porosity_floor") as caught:
            advance(scene, 20)
        found.append([str(w.message) for w in caught if "porosity_floor" in str(w.message)])
        assert scene.state.clock.step == 27
    assert found[0] == found[1] and len(found[0]) == 1
    assert found[0][0].startswith("step 7: porosity 0.05 in fluid cell")
    assert "(192 particle(s) this step" in found[0][0]


def test_a_darcy_fluid_keeps_the_step_by_step_loop():
    """Darcy's force on the particles (and on a wall it pushes) has no compiled loop."""
    assert build_scene(load_case(CONFIGS / "seepage-pulses-darcy.toml")).step.compiled is None


def test_a_wrapped_hook_keeps_the_step_by_step_loop():
    """A hook replaced by a wrapper (a benchmark's stopwatch) is called: no compiled steps."""
    scene = build_scene(load_case(CONFIGS / "demo.toml"))
    contact = scene.contact
    original = contact.forces
    contact.forces = lambda state, spring_dt=None: original(state, spring_dt)
    scene.order_modules()
    assert scene.step.compiled is None


def test_a_subclass_with_forces_of_its_own_keeps_the_step_by_step_loop():
    """A module whose forces hook is overridden does not inherit the compiled loop of its base
    (the loop would skip whatever the override adds)."""
    scene = build_scene(load_case(CONFIGS / "bedload.toml"))
    assert scene.step.compiled is not None and scene.step.compiled.fluid is scene.fluid
    base = type(scene.fluid)
    scene.fluid.__class__ = type("Wrapped", (base,), {"forces": lambda self, s, spring_dt=None: None})
    scene.order_modules()
    assert scene.step.compiled is None


def test_the_compiled_loops_take_no_function_arguments():
    """A kernel passed as an argument keys Numba's cache by an object that is new in every
    process: that loop would compile on every run and add a cache file each time."""
    for case in (load_case(CONFIGS / "bedload.toml"), _fluidized("particle")):
        advance(build_scene(case), 50)
    loops = (dem_steps, vans1d_steps, dem_steps_serial, vans1d_steps_serial, drag_steps, drag_steps_serial)
    for loop in loops:
        for signature in loop.signatures:
            assert not any(isinstance(t, (types.Dispatcher, types.Function)) for t in signature)
    assert vans1d_steps.signatures or vans1d_steps_serial.signatures
    assert drag_steps.signatures or drag_steps_serial.signatures


def test_run_frames_and_checkpoints_fall_on_their_steps(tmp_path):
    """The run loop takes steps in bursts (simulation.Loop); the frames, checkpoints and the
    end still fall on the steps of their schedules."""
    case = tmp_path / "case.toml"
    text = canonical_case(64, duration=53 * 4.0e-6)
    text = text.replace("[output.frames]\nevery_time", "[output.frames]\nevery_steps = 7\n#")
    text = text.replace("[output.checkpoints]\nevery_time", "[output.checkpoints]\nevery_steps = 10\n#")
    text = text.replace("keep = 1", "keep = 20")
    case.write_text(text)
    api.run(case, tmp_path / "run")
    with h5py.File(tmp_path / "run" / "trajectory.h5", "r") as f:
        frames = list(f["particles/trajectory/position/step"][...])
    assert frames == [0, 7, 14, 21, 28, 35, 42, 49, 53]
    checkpoints = [read_checkpoint(c).step for c in list_checkpoints(tmp_path / "run" / "checkpoints")]
    assert checkpoints == [0, 10, 20, 30, 40, 50, 53]  # the first one at the start


@pytest.mark.parametrize("name", ["hertz-mixture", "canonical", "periodic", "bedload"])
def test_one_thread_runs_the_serial_twins_bitwise_as_two_threads_run_the_parallel_kernels(name, monkeypatch):
    """kernels/serial.py: on one thread the hooks and the compiled loops run the kernels' serial
    twins (compiled without reference counting, the leaf kernels with their arrays declared
    distinct); on two threads the parallel kernels. The runs are bitwise the same."""
    loop = vans1d_steps_serial if name == "bedload" else dem_steps_serial
    loop = vans1d_steps_serial if name == "bedload" else dem_steps_serial
    runs = {}
    try:
        for threads in (2, 1):
            numba.set_num_threads(threads)
            calls = []
            for module, twin in (
                (motion_module, "kick_serial"),
                (contact_module, "chunk_pair_forces_serial"),
            ):
                kernel = getattr(module, twin)
                monkeypatch.setattr(module, twin, lambda *a, c=calls, k=kernel, n=twin: c.append(n) or k(*a))
            scene = build_scene(_case(name))
            advance(scene, STEPS)
            assert scene.state.neighbors.builds >= 2
            runs[threads] = _state(scene)
            # the list builds end their steps through the hooks: the twins there on one thread
            assert set(calls) == ({"kick_serial", "chunk_pair_forces_serial"} if threads == 1 else set())
            if threads == 1:
                assert loop.overloads  # the compiled loop's twin, called from Python (compiled or loaded)
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    for key in runs[1]:
        assert np.array_equal(runs[1][key], runs[2][key]), key


def test_the_serial_twins_run_on_one_thread_at_every_size(monkeypatch):
    calls = []
    monkeypatch.setattr(motion_module, "kick_serial", lambda *args: calls.append("serial"))
    monkeypatch.setattr(motion_module, "kick", lambda *args: calls.append("parallel"))
    scenes = [build_scene(parse_case(canonical_case(n))) for n in (8, 1000)]
    try:
        for threads in (1, 2):
            numba.set_num_threads(threads)
            for each in scenes:
                next(m for m in each.modules if m.name == "particles").kick(each.state)
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    assert calls == ["serial", "serial", "parallel", "parallel"]


def _written_elsewhere(arguments: tuple, written: set[int]) -> list[tuple[int, int]]:
    """Pairs (k, m) of non-empty array arguments that share memory, one of them written."""
    arrays = [(k, a) for k, a in enumerate(arguments) if isinstance(a, np.ndarray) and a.size]
    return [
        (k, m)
        for n, (k, a) in enumerate(arrays)
        for m, b in arrays[n + 1 :]
        if (k in written or m in written) and np.shares_memory(a, b)
    ]


@pytest.mark.parametrize(
    "name",
    [
        "hertz-mixture",
        "canonical",
        "periodic",
        "bedload",
        "direct-shear",
        "fluidized-bed",
        "direct-shear-budget",
    ],
)
def test_the_twins_declared_distinct_get_arrays_that_share_no_memory(name):
    """kernels/serial.py: a twin marked `distinct` is compiled with its array arguments declared
    not to overlap; where an argument it writes shared memory with another, the compiler could
    reorder their reads and writes. The argument tuples the scenes give them share none."""
    from sphere_cli.kernels.contact import chunk_pair_forces
    from sphere_cli.kernels.fluid.drag import drag_kick, particle_drag
    from sphere_cli.kernels.fluid.porosity import bin_particles
    from sphere_cli.kernels.fluid.profile_forces import profile_forces
    from sphere_cli.kernels.motion import kick, kick_drift
    from sphere_cli.kernels.observe.energy_budget import accumulate_budget
    from sphere_cli.kernels.walls import wall_forces
    from sphere_cli.physics.compiled_steps import step_arguments
    from sphere_cli.physics.contact import PairContactForces
    from sphere_cli.physics.walls import PlaneWallForces

    def written(kernel, names):
        params = list(kernel.py_func.__code__.co_varnames[: kernel.py_func.__code__.co_argcount])
        return {params.index(n) for n in names}

    if name == "fluidized-bed":
        scene = build_scene(_fluidized("particle"))
    elif name == "direct-shear":
        scene = build_scene(load_case(CONFIGS / "direct-shear.toml"))
    elif name == "direct-shear-budget":
        scene = build_scene(_direct_shear())
    else:
        scene = build_scene(_case(name))
    advance(scene, 200)
    contact = next(m for m in scene.modules if isinstance(m, PairContactForces))
    walls = next((m for m in scene.modules if isinstance(m, PlaneWallForces)), None)
    drift, _, pairs, wall, kicks = step_arguments(scene.state, contact, walls)
    checked = [
        (drift, written(kick_drift, ("pos", "vel", "angvel", "vel_pred", "angvel_pred"))),
        (kicks, written(kick, ("vel", "angvel"))),
        (
            pairs,
            written(
                chunk_pair_forces, ("hist", "slots", "blocks", "block_ids", "block_rows", "force", "torque")
            ),
        ),
    ]
    if wall is not None:
        names = ("wall_hist", "force", "torque", "pforce", "springs", "blocks", "block_ids")
        checked.append((wall, written(wall_forces, names)))
    if name == "bedload":
        fluid = next(m for m in scene.modules if hasattr(m, "force_arguments"))
        checked.append(
            (fluid.force_arguments(scene.state), written(profile_forces, ("force", "drag_coef", "drag_x")))
        )
    if name == "fluidized-bed":
        binning, drag, _, _, _ = scene.fluid.force_arguments(scene.state)
        written_by_drag = ("force", "f_other", "coef", "f_drag")
        written_by_kick = ("vel", "angvel", "force", "f_drag", "impulse", "disturbance")
        checked += [
            (binning, written(bin_particles, ("bin_of", "wrapped"))),
            (drag, written(particle_drag, written_by_drag)),
            (scene.fluid.kick_arguments(scene.state), written(drag_kick, written_by_kick)),
        ]
    if scene.budget is not None:
        checked.append(
            (scene.budget.book_arguments(scene.state), written(accumulate_budget, ("scratch", "booked")))
        )
    for arguments, writes in checked:
        assert writes
        assert _written_elsewhere(arguments, writes) == []


def test_the_serial_twins_are_cached_apart_from_their_kernels():
    """A twin without Numba's cache would compile in every process (seconds per run); with the
    kernel's own name it would overwrite the kernel's cache entry."""
    twins = {
        kernels_motion: ("kick_drift", "kick"),
        kernels_walls: ("wall_forces",),
        kernels_steps: ("contacts", "dem_steps"),
        kernels_contact: ("chunk_pair_forces",),
        kernels_profile: ("profile_forces", "vans1d_steps"),
        kernels_drag: ("particle_drag", "drag_kick", "drag_steps"),
        kernels_porosity: ("bin_particles",),
        kernels_budget: ("accumulate_budget",),
    }
    for module, names in twins.items():
        for name in names:
            twin, kernel = getattr(module, f"{name}_serial"), getattr(module, name)
            assert twin._cache._cache_path == kernel._cache._cache_path
            assert twin._cache._cache_file._index_path != kernel._cache._cache_file._index_path
    # the loops' variants with the VANS force (kernels/serial.py variant): each its own entry
    loops = (dem_steps, dem_steps_serial, vans1d_steps, vans1d_steps_serial)
    assert len({loop._cache._cache_file._index_path for loop in loops}) == len(loops)
