"""One scene split across MPI ranks (sphere_cli/ranks.py, physics/rank_steps.py), run with the real
launcher: the mpich wheel's `mpiexec` (test extra) starting `sphere run` / `sphere resume`.

A split run must be bitwise a one-rank run, whatever the rank count: its trajectory (every
dataset h5py reads, provenance aside) and its checkpoints. The scenes are chosen so that ranks
matter: beads sliding fast across a periodic cut axis (each crosses every rank boundary many
times, carrying its pair and wall springs), and a bed settling in a box with walls on the cut
axis (an open cut axis, particles pressed against the end walls).
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import h5py
import numpy as np
import pytest
from cli_test_support import edit
from test_fluid_moving_grid_input import DARCY_FOLLOWING, DARCY_TOP_WALL
from test_vans1d_bad_input import CASE as VANS_CASE

from sphere_cli.io.checkpoint import list_checkpoints, newest_valid_checkpoint
from sphere_cli.verify.coupled_cases import OEDOMETER

MPIEXEC = Path(sys.executable).with_name("mpiexec")
REPO = Path(__file__).resolve().parents[2]
pytestmark = pytest.mark.skipif(
    not MPIEXEC.is_file() or shutil.which("mpiexec", path=str(MPIEXEC.parent)) is None,
    reason="no mpiexec beside this Python (the test extra installs the mpich wheel on Linux)",
)

# 120 beads on a floor in a periodic box 12 mm long, sliding at 0.8 m/s along x (the cut axis:
# five search cells) with spin, friction and rolling resistance: in 0.04 s each crosses the box
# about 2.7 times, changing rank with its springs several times on two ranks, and about once or
# twice in the last 5 ms, which run on four.
SLIDING = """\
[simulation]
duration = 0.04
dt = "auto"

[domain]
lower = [0.0, 0.0, 0.0]
upper = [0.012, 0.006, 0.008]
periodic = [true, true, false]
gravity = [0.0, 0.0, -9.81]

[particles]
count = 120
density = 2500.0
seed = 3
radius = { distribution = "uniform", min = 0.0005, max = 0.0006 }
placement = { method = "random" }
velocity = [0.8, 0.0, 0.0]
angular_velocity = [0.0, 200.0, 50.0]

[contact]
model = "linear"
normal_stiffness = 2.0e3
restitution = 0.5
friction = 0.5
rolling_friction = 0.1

[[walls]]
face = "z-"
friction = 0.4

[output]
status_every_seconds = 0.2

[output.frames]
every_time = 0.01

[output.checkpoints]
every_time = 0.01
keep = 10

[output.observables]
quantities = ["energy", "contacts", "coordination", "stress"]
"""

# 200 Hertz-Mindlin spheres of two materials thrown onto the floor of a box with walls on every
# side but the top, from a loose random packing (solid fraction 0.2): the bed piles up within the
# first milliseconds, so pairs across the cuts touch; the cut axis x is open, its end slabs
# against walls. Its slabs are cut by measured work (rank_balance, ignored on one rank).
SETTLING = """\
[simulation]
duration = 0.006
dt = "auto"
rank_balance = "time"

[domain]
lower = [0.0, 0.0, 0.0]
upper = [0.016, 0.006, 0.012]

[particles]
count = 200
seed = 11
radius = { distribution = "uniform", min = 0.0005, max = 0.0007 }
placement = { method = "random", region_upper = [0.016, 0.006, 0.009] }
velocity = [0.0, 0.0, -0.3]
material = { glass = 0.5, steel = 0.5 }

[contact]
model = "hertz-mindlin"
restitution = 0.4
friction = 0.3

[[materials]]
name = "glass"
density = 2500.0
youngs_modulus = 5.0e6
poisson_ratio = 0.22

[[materials]]
name = "steel"
density = 7800.0
youngs_modulus = 1.5e7
poisson_ratio = 0.3

[[walls]]
face = "z-"
[[walls]]
face = "x-"
[[walls]]
face = "x+"
[[walls]]
face = "y-"
[[walls]]
face = "y+"

[output.frames]
every_time = 0.003

[output.checkpoints]
every_time = 0.003
keep = 10
"""


# one thread a rank; waits that sleep, not spin: up to four ranks share the runner's two cores
# with the other test worker, and MPICH's busy polling would take the cores the ranks wait for
# (its progress throttle sleeps 1 us after 100 polls that found nothing; the 4-rank resume test
# took 52 s instead of 61 s beside a busy core)
RANK_ENV = {
    "OMP_WAIT_POLICY": "PASSIVE",
    "NUMBA_NUM_THREADS": "1",
    "MPIR_CVAR_CH4_PROGRESS_THROTTLE": "1",
    "MPIR_CVAR_CH4_PROGRESS_THROTTLE_NO_PROGRESS_COUNT": "100",
}


def sphere(*args, ranks: int = 1, cwd: Path, timeout: float = 300) -> subprocess.CompletedProcess:
    """`sphere ARGS` as one process, or on `ranks` ranks through mpiexec."""
    command = [sys.executable, "-m", "sphere_cli", *args]
    if ranks > 1:
        command = [str(MPIEXEC), "-n", str(ranks), *command]
    env = {**os.environ, **RANK_ENV}
    return subprocess.run(command, cwd=cwd, capture_output=True, text=True, timeout=timeout, env=env)


def datasets(path: Path) -> dict:
    """Every dataset of an HDF5 file, by name (the provenance records aside: host, command, ...)."""
    out = {}
    with h5py.File(path, "r") as f:

        def visit(name, obj):
            if isinstance(obj, h5py.Dataset) and "provenance" not in name and "resumes" not in name:
                out[name] = obj[()]

        f.visititems(visit)
    return out


def assert_bitwise(a: Path, b: Path) -> None:
    one, other = datasets(a), datasets(b)
    assert one.keys() == other.keys(), sorted(set(one) ^ set(other))
    for name, value in one.items():
        if isinstance(value, np.ndarray):
            assert value.shape == other[name].shape and value.tobytes() == other[name].tobytes(), name
        else:
            assert value == other[name], name


def assert_runs_bitwise(one: Path, split: Path) -> None:
    """Trajectories, and every checkpoint the split run wrote, bitwise those of one rank."""
    assert_bitwise(one / "trajectory.h5", split / "trajectory.h5")
    written = list_checkpoints(split / "checkpoints")
    assert written
    for path in written:
        assert_bitwise(one / "checkpoints" / path.name, path)


def run_ok(result: subprocess.CompletedProcess) -> None:
    assert result.returncode == 0, result.stdout + result.stderr
    assert "Traceback" not in result.stderr


@pytest.fixture(scope="module")
def sliding(tmp_path_factory) -> Path:
    """The sliding beads' case, and its one-rank run `one`, stopped at t = 0.035 s (a frame and
    the observables are written there, as where the split run stops) and resumed to the end."""
    root = tmp_path_factory.mktemp("sliding")
    (root / "case.toml").write_text(SLIDING)
    run_ok(sphere("run", "case.toml", "-o", "one", "-q", "--until", "0.035", cwd=root))
    run_ok(sphere("resume", "one", "-q", cwd=root))
    return root


def test_a_two_rank_checkpoint_resumes_on_one_and_four_ranks_bitwise(sliding):
    """2 ranks to t = 0.035 s, then on 4 ranks and on 1 to the end: every frame and checkpoint is
    one rank's, springs included (the beads change rank across the cuts, and where the cut axis
    turns between z, while the beads fall and bounce, and x, as they slide: by t = 0.035 s each
    has crossed the box about twice, and on 4 ranks it slides about 4 mm more, a third of it).
    The 4-rank leg is the last eighth: four ranks on a 2-core runner beside another test step
    at a fraction of one rank's speed."""
    root = sliding
    run_ok(sphere("run", "case.toml", "-o", "two", "-q", "--until", "0.035", ranks=2, cwd=root))
    log = (root / "two" / "run.log").read_text()
    assert "split across 2 MPI ranks" in log
    status = json.loads((root / "two" / "status.json").read_text())
    assert status["ranks"] == 2
    with h5py.File(root / "two" / "trajectory.h5", "r") as f:
        assert f["sphere/provenance"].attrs["mpi_ranks"] == 2
    shutil.copytree(root / "two", root / "then-one")
    run_ok(sphere("resume", "two", "-q", ranks=4, cwd=root))
    assert "split across 4 MPI ranks" in (root / "two" / "run.log").read_text()
    run_ok(sphere("resume", "then-one", "-q", cwd=root))
    for resumed in ("two", "then-one"):
        assert_runs_bitwise(root / "one", root / resumed)
    springs = datasets(
        root / "one" / list_checkpoints(root / "one" / "checkpoints")[-1].relative_to(root / "one")
    )
    assert np.count_nonzero(springs["sphere/state/neighbors/hist"]) > 0  # pairs with history
    assert np.count_nonzero(springs["sphere/state/walls/hist"]) > 0


def test_a_bed_settling_between_walls_is_one_ranks_on_three_and_four(tmp_path):
    """On three ranks the box is cut into slabs. On four, 300 of the spheres settling in a
    square box between walls, into pencils of 2 x 2 at every list build: a rank's ghosts lie on
    two sides and across a corner, where pairs touch diagonally, and particles move between four
    ranks. One rank's run either way (the four-rank run fails without the diagonal ghosts). On
    four, a stage from the start moves the lid down at 0.4 m/s (past the reach of the near-wall
    list: it is made again) and the x+ wall keeps 100 +- 50 Pa at 300 Hz on the bed (its target
    follows the step's time): the particles' pushes on it,
    summed over every rank in the compiled rank loop (kernels/rank_messages.py
    rank_wall_totals), and the walls' motion are one rank's too."""
    square = SETTLING
    for old, new in (
        ("upper = [0.016, 0.006, 0.012]", "upper = [0.012, 0.012, 0.012]"),
        ("region_upper = [0.016, 0.006, 0.009]", "region_upper = [0.012, 0.012, 0.009]"),
        ("count = 200", "count = 300"),
        ("duration = 0.006", "duration = 0.01"),  # 10 ms: a 6 ms run passed with no diagonal ghosts
        ('face = "y+"\n', 'face = "y+"\n[[walls]]\nface = "z+"\n'),
        (
            "[output.frames]",
            '[[stages]]\nname = "press"\nduration = 0.01\n[[stages.walls]]\nface = "z+"\nmode = "velocity"\n'
            'velocity = 0.4\n[[stages.walls]]\nface = "x+"\nmode = "stress"\nstress = 100.0\n'
            "stress_amplitude = 50.0\nfrequency = 300.0\n\n[output.frames]",
        ),
    ):
        assert old in square
        square = square.replace(old, new)
    square += '\n[output.observables]\nquantities = ["stress"]\n'
    for ranks, case in ((3, SETTLING), (4, square)):
        root = tmp_path / str(ranks)
        root.mkdir()
        (root / "case.toml").write_text(case)
        run_ok(sphere("run", "case.toml", "-o", "one", "-q", cwd=root))
        run_ok(sphere("run", "case.toml", "-o", "split", "-q", ranks=ranks, cwd=root))
        assert "cut by measured work" in (root / "split" / "run.log").read_text()
        assert_runs_bitwise(root / "one", root / "split")
    with h5py.File(tmp_path / "4" / "one" / "trajectory.h5", "r") as f:
        assert f["observables/wall_normal_stress/value"][-1, 2] > 10.0  # x+ (of z-, x-, x+, ...) pushed
        assert f["observables/wall_position/value"][-1, 5] < 0.009  # the lid moved down 3 mm


def test_direct_shear_with_stages_and_a_stress_controlled_wall_is_one_ranks_on_two(tmp_path):
    """configs/direct-shear.toml, its stages shortened: deposit (frictionless, a kinetic-energy
    stop), consolidate (the top wall approaches, then keeps 1 kPa) and shear (the rough top wall
    moves sideways): the moving walls' forces are summed exactly over the ranks, and
    the walls, the glued spheres and the friction set by each stage reach every rank. With the
    energy budget: each rank books its own particles' shares (their rows as one rank has them),
    which travel with them, so its observables and checkpoints are one rank's too. The walls'
    motion and the budget run inside each rank's compiled steps."""
    text = (REPO / "configs" / "direct-shear.toml").read_text()
    assert text.count("\nquantities = [") == 1
    text = text.replace("\nquantities = [", '\nquantities = ["energy_budget", ')
    for old, new in (("duration = 0.15", "duration = 0.012"), ("min_time = 0.06", "min_time = 0.006")):
        text = text.replace(old, new)
    text = text.replace("duration = 0.05", "duration = 0.008").replace("duration = 0.08", "duration = 0.008")
    (tmp_path / "case.toml").write_text(text)
    run_ok(sphere("run", "case.toml", "-o", "one", "-q", cwd=tmp_path))
    run_ok(sphere("run", "case.toml", "-o", "two", "-q", ranks=2, cwd=tmp_path))
    log = (tmp_path / "two" / "run.log").read_text()
    assert "now: consolidate" in log and "now: shear" in log and "now: finished" in log
    assert "steps up to a list build in one compiled call" in log  # walls and budget inside
    assert_runs_bitwise(tmp_path / "one", tmp_path / "two")
    with h5py.File(tmp_path / "one" / "trajectory.h5", "r") as f:
        top = f["observables/wall_position/value"][:, 1]
        assert top[-1] < top[0] - 0.001  # the top wall came down onto the bed
        # the budget is booked (the top wall has not reached the bed in this short run)
        assert f["observables/dissipated_damping/value"][-1] > 0.0
        assert f["observables/work_gravity/value"][-1] > 0.0


def test_bedload_with_turbulent_fluctuations_is_one_ranks_on_three(tmp_path):
    """configs/bedload.toml (a 1D VANS fluid over a bed of 1 000 beads) with turbulent
    fluctuations: the fluid steps at rank 0 on the whole bed, its profiles reach every rank, and
    each particle's drag and fluctuation travel with it between ranks. The fluid's force runs
    inside each rank's compiled steps."""
    text = (REPO / "configs" / "bedload.toml").read_text()
    text = text.replace("cells = 70 ", "fluctuations = { bed_elevation = 0.012 }\ncells = 70 ")
    (tmp_path / "case.toml").write_text(text)
    shutil.copy(REPO / "configs" / "bedload-bed.csv", tmp_path)
    run_ok(sphere("run", "case.toml", "-o", "one", "-q", "--until", "0.03", cwd=tmp_path))
    run_ok(sphere("run", "case.toml", "-o", "three", "-q", "--until", "0.03", ranks=3, cwd=tmp_path))
    # the fluid's force inside the compiled rank loop (kernels/rank_messages.py), not from Python
    assert "steps up to a list build in one compiled call" in (tmp_path / "three" / "run.log").read_text()
    assert_runs_bitwise(tmp_path / "one", tmp_path / "three")
    state = datasets(list_checkpoints(tmp_path / "one" / "checkpoints")[-1])
    assert np.count_nonzero(state["sphere/state/fluid/fluctuation"]) > 100  # drawn, and compared


def test_a_navier_stokes_bed_is_one_ranks_on_two_then_four(tmp_path):
    """configs/fluid-settling.toml as a bed: 500 beads in a touching lattice settle in water onto
    the floor, the cuts through the bed (across its width). The fluid steps every 10 steps, on
    every rank from every rank's particles and their drag arrays; the drag and the implicit kick
    run on every rank for its particles. A ghost's drag needs its owner's other forces (its
    contacts beyond the ghosts) and each particle's self-induced velocity the drag coefficients
    of its whole fluid cell, summed over every rank in one rank's order (sent from inside the
    compiled rank loop; it fails if the rows received are left out of the sums). Run on 2 ranks
    to t = 1 ms, then resumed on 4 with the slabs cut by measured work: one rank's run-then-resume, bit
    for bit, with the pressure solve split across the ranks (rank_split_cells = 1: the grid's 5
    planes in 2 slabs; on resume 50, which a resume accepts changed: 4 slabs). The bed's cells
    are below a porosity floor of 0.5 (a touching cubic lattice leaves 0.48): the fluid step's
    warning of it is written once a run, by rank 0, not once a rank."""
    text = (REPO / "configs" / "fluid-settling.toml").read_text()
    for old, new in (
        ("count = 200", "count = 500"),
        (
            '{ distribution = "uniform", min = 0.0003, max = 0.0004 }',
            '{ distribution = "fixed", value = 0.0004 }',
        ),
        (
            '"random", region_lower = [0.0, 0.0, 0.008], region_upper = [0.01, 0.01, 0.02] }',
            '"lattice", spacing = 1.0, jitter = 0.05, region_upper = [0.01, 0.01, 0.006] }',
        ),
        ("duration = 0.1", "duration = 0.002"),
        ("every_time = 0.01", "every_time = 0.0005"),
        ("every_time = 0.05\nkeep = 2", "every_time = 0.001\nkeep = 10"),
        (
            "[output.frames]",
            "[fluid.drag]\nporosity_floor = 0.5\n\n[fluid.solver]\nrank_split_cells = 1\n\n[output.frames]",
        ),
    ):
        assert old in text, old
        text = text.replace(old, new)
    (tmp_path / "case.toml").write_text(text)
    run_ok(sphere("run", "case.toml", "-o", "one", "-q", "--until", "0.001", cwd=tmp_path))
    run_ok(sphere("resume", "one", "-q", cwd=tmp_path))
    split = [sphere("run", "case.toml", "-o", "split", "-q", "--until", "0.001", ranks=2, cwd=tmp_path)]
    edited = tmp_path / "split" / "case.toml"  # a resume may change how the slabs are cut
    text = edited.read_text().replace("[simulation]", '[simulation]\nrank_balance = "time"')
    assert "rank_split_cells = 1\n" in text
    edited.write_text(text.replace("rank_split_cells = 1\n", "rank_split_cells = 50\n"))
    split.append(sphere("resume", "split", "-q", ranks=4, cwd=tmp_path))
    for result in split:
        run_ok(result)
        assert result.stderr.count("the fluid and the drag use the floor there") == 1, result.stderr
    log = (tmp_path / "split" / "run.log").read_text()
    assert "split across 2 MPI ranks" in log and "split across 4 MPI ranks" in log
    assert "cut by measured work" in log
    # the drag's kick sums over every rank's particles in a cell from inside the compiled loop
    assert "steps up to a list build in one compiled call" in log
    assert_runs_bitwise(tmp_path / "one", tmp_path / "split")
    state = datasets(list_checkpoints(tmp_path / "one" / "checkpoints")[-1])
    assert np.count_nonzero(state["sphere/state/neighbors/hist"]) > 1000  # a bed in contact
    assert np.count_nonzero(state["sphere/state/fluid/drag_self_induced"]) > 0


def test_ranks_without_particles_step_from_python_beside_ranks_in_the_compiled_loop(tmp_path):
    """One bead settling in water (configs/fluid-settling.toml, the default drag) on 4 ranks: a
    rank holding no particle steps one step at a time from Python while the rank owning the
    bead takes its steps in the drag's compiled loop, with the same messages (the ghosts'
    forces and the drag's coefficient rows: RankSteps._swap against kernels/rank_messages.py
    send_ghost_forces) and the same collectives, those of the fluid's steps included, which a
    rank whose slab's cells reach no particle takes as the others do (before, such a rank
    skipped the porosity's messages and the others waited for it: a hang). One rank's run,
    bit for bit."""
    text = (REPO / "configs" / "fluid-settling.toml").read_text()
    for old, new in (
        ("count = 200\n", "count = 1\n"),
        ("duration = 0.1", "duration = 0.001"),
        ("every_time = 0.01", "every_time = 0.0005"),
        ("every_time = 0.05\nkeep = 2", "every_time = 0.001\nkeep = 2"),
    ):
        assert old in text, old
        text = text.replace(old, new)
    (tmp_path / "case.toml").write_text(text)
    run_ok(sphere("run", "case.toml", "-o", "one", "-q", cwd=tmp_path))
    run_ok(sphere("run", "case.toml", "-o", "split", "-q", ranks=4, cwd=tmp_path, timeout=120))
    assert "steps up to a list build in one compiled call" in (tmp_path / "split" / "run.log").read_text()
    assert_runs_bitwise(tmp_path / "one", tmp_path / "split")


def oedometer() -> str:
    """The undrained oedometer of `sphere verify`'s d5-darcy-undrained-skempton
    (sphere_cli/verify/coupled_cases.py), 1.5 ms of it: 128 spheres in 8 touching layers between
    a floor and a top wall held at 2 kPa, the Darcy grid following the wall, which the pore
    pressure under it pushes up (no gravity)."""
    text = OEDOMETER.format(stress=2000.0, compressibility=1e-7, top='{ type = "no-flow" }')
    assert "duration = 1.0" in text
    outputs = "\n[output.frames]\nevery_time = 0.0005\n[output.checkpoints]\nevery_time = 0.0005\nkeep = 10\n"
    return (
        text.replace("duration = 1.0", "duration = 0.0015")
        + outputs
        + '[output.observables]\nquantities = ["stress"]\n'
    )


def test_a_darcy_oedometer_with_the_pore_pressure_on_its_wall_is_one_ranks_on_two(tmp_path):
    """Every rank steps the pore pressure from the porosity of the whole bed, and each adds its
    push on the stress-controlled top wall (the wall's force observable included). The bed's
    porosity, 0.397, is clamped at 0.4: the warning is logged once, by rank 0 (run.log and
    the launcher's stderr), not once a rank. The pore pressure's solve is split (the grid's 2
    planes, one a rank)."""
    assert "porosity_max = 0.6" in oedometer()
    text = oedometer().replace("porosity_max = 0.6", "porosity_min = 0.4\nporosity_max = 0.6")
    (tmp_path / "case.toml").write_text(text + "[fluid.solver]\nrank_split_cells = 1\n")
    run_ok(sphere("run", "case.toml", "-o", "one", "-q", cwd=tmp_path))
    split = sphere("run", "case.toml", "-o", "two", "-q", ranks=2, cwd=tmp_path)
    run_ok(split)
    warning = "Darcy: porosity below fluid.porosity_min = 0.4"
    assert (tmp_path / "two" / "run.log").read_text().count(warning) == 1
    assert split.stderr.count(warning) == 1, split.stderr
    assert_runs_bitwise(tmp_path / "one", tmp_path / "two")
    with h5py.File(tmp_path / "one" / "trajectory.h5", "r") as f:
        pushed = f["observables/wall_force/value"][-1, 1, 2]
    assert pushed > 0.5 * 2000.0 * 0.004**2  # the pore pressure carries most of the load


# 200 beads placed at random, settling under a Darcy grid of 8 x 2 x 6 cells of 2 mm in a box
# periodic along x and y: each rank samples the porosity of its slab of x planes from the
# particles those cells reach (the sampling reach is one plane), not from every particle.
DARCY_SLABS = """\
[simulation]
duration = 0.002
dt = "auto"

[domain]
upper = [0.016, 0.004, 0.012]
periodic = [true, true, false]

[particles]
count = 200
density = 2500.0
radius = { distribution = "uniform", min = 0.0004, max = 0.0005 }
placement = { method = "random", region_upper = [0.016, 0.004, 0.008] }

[contact]
model = "linear"
normal_stiffness = 100.0
restitution = 0.5
friction = 0.3

[fluid]
model = "darcy"
grid = { cells = [8, 2, 6] }
permeability = { model = "kozeny-carman" }
compressibility = 1e-8
top = { type = "pressure", pressure = 0.0 }
bottom = { type = "no-flow" }

[fluid.solver]
rank_split_cells = 1

[fluid.coupling]
steps = 5

[output.frames]
every_time = 0.001

[output.checkpoints]
every_time = 0.002
keep = 2
"""


# beads of the same size in two touching layers (a lattice, jittered: pairs in contact across
# the cuts) in water under a Navier-Stokes grid of the same cells, with the drag of each particle
# (its self-induced velocity kept here, subtracted in the bed of
# test_a_navier_stokes_bed_is_one_ranks_on_two_then_four; both in the compiled rank loop, where
# each ghost's kick needs its owner's other forces) or the cell-averaged drag
NAVIER_STOKES_SLABS = (
    DARCY_SLABS[: DARCY_SLABS.index("[fluid]")]
    .replace(
        '{ distribution = "uniform", min = 0.0004, max = 0.0005 }',
        '{ distribution = "fixed", value = 0.0004 }',
    )
    .replace(
        '{ method = "random", region_upper = [0.016, 0.004, 0.008] }',
        '{ method = "lattice", spacing = 1.0, jitter = 0.05 }',
    )
    + """\
[fluid]
model = "navier-stokes"
density = 1000.0
viscosity = 1.0e-3
grid = { cells = [8, 2, 6] }
bottom = { type = "no-flow" }
top = { type = "pressure", pressure = 0.0 }

[fluid.solver]
rank_split_cells = 1

[fluid.coupling]
steps = 5
"""
    + DARCY_SLABS[DARCY_SLABS.index("[output.frames]") - 1 :]
    + '\n[fluid.drag]\nself_induced = "keep"\n'
)


# with the cell-averaged drag, three layers of beads under a lid pressed down by 4 kPa that the
# grid follows (its cells' height changes at every fluid step) and that lands on the top layer
# (its pushes summed over every rank move it), its solve left whole (32 cells, under
# rank_split_cells a rank): the porosity and the exchange on the planes shared out evenly
NAVIER_STOKES_LID = (
    NAVIER_STOKES_SLABS.replace(
        "[fluid]\n", '[[walls]]\nface = "z+"\nmode = "stress"\nstress = 4000.0\n\n[fluid]\n'
    )
    .replace("count = 200", "count = 300")
    .replace("upper = [0.016, 0.004, 0.012]", "upper = [0.016, 0.004, 0.0029]")
    .replace("grid = { cells = [8, 2, 6] }", "grid = { cells = [8, 2, 2], follow_top_wall = true }")
    .replace("rank_split_cells = 1", "rank_split_cells = 4096")
    .replace('self_induced = "keep"', 'averaging = "cell"')
)
# the same with the drag of each particle less its self-induced velocity: its cells' sums over
# every rank planned by columns once a list build (the grid's cells change with the lid)
NAVIER_STOKES_LID_SUBTRACTED = NAVIER_STOKES_LID.replace('averaging = "cell"', 'self_induced = "subtract"')


@pytest.mark.parametrize(
    "case",
    [DARCY_SLABS, NAVIER_STOKES_SLABS, NAVIER_STOKES_LID, NAVIER_STOKES_LID_SUBTRACTED],
    ids=["darcy", "navier-stokes", "navier-stokes-cell-averaged-lid", "navier-stokes-lid"],
)
def test_a_fluid_bed_on_slabs_is_one_ranks_on_two_and_three(case, tmp_path):
    """Its porosity (and mean particle velocity) is sampled, and the Navier-Stokes momentum
    exchange settled, on slabs of 4 and 4, then 2, 3 and 3 x planes (those of the pressure
    solve, or where it is not split the planes shared out evenly), each rank from only the
    particles its cells reach (RankSteps._near: a window of its planes and one either side,
    wrapped), sorted back into global order, and the cells' fields gathered: bit for bit one
    rank's. It fails if the window leaves out the plane on either side of a slab, or a rank's
    cells are not gathered. The Navier-Stokes beds, under the lid too, take their steps in the
    compiled rank loop of the drag (kernels/fluid/drag.py rank_drag_steps)."""
    (tmp_path / "case.toml").write_text(case)
    run_ok(sphere("run", "case.toml", "-o", "one", "-q", cwd=tmp_path))
    # the Navier-Stokes beds on 3 ranks alone (the suite's time; the bed of
    # test_a_navier_stokes_bed_is_one_ranks_on_two_then_four runs on 2)
    for ranks in (2, 3) if case == DARCY_SLABS else (3,):
        run_ok(sphere("run", "case.toml", "-o", f"split{ranks}", "-q", ranks=ranks, cwd=tmp_path))
        assert_runs_bitwise(tmp_path / "one", tmp_path / f"split{ranks}")
        log = (tmp_path / f"split{ranks}" / "run.log").read_text()
        assert ("steps up to a list build in one compiled call" in log) == (case != DARCY_SLABS)
    if case == NAVIER_STOKES_SLABS:  # a bed in contact
        state = datasets(list_checkpoints(tmp_path / "one" / "checkpoints")[-1])
        assert np.count_nonzero(state["sphere/state/neighbors/hist"]) > 100
    if case in (NAVIER_STOKES_LID, NAVIER_STOKES_LID_SUBTRACTED):  # the lid on the top layer
        with h5py.File(tmp_path / "one" / "trajectory.h5", "r") as f:
            assert f["observables/wall_contacts/value"][-1] == 100


def _wait_for(condition, process, seconds: float = 120.0) -> None:
    deadline = time.monotonic() + seconds
    while not condition():
        assert process.poll() is None, process.communicate()
        assert time.monotonic() < deadline
        time.sleep(0.05)


def _pids(log: Path, launches: int) -> list[int]:
    """The ranks' process ids that run.log gives for the `launches`-th split start (none yet: [])."""
    lines = [line for line in log.read_text().splitlines() if "process ids by rank:" in line]
    if len(lines) < launches:
        return []
    return [int(x) for x in lines[launches - 1].split("process ids by rank:")[1].strip(" )").split()]


def test_stops_and_a_killed_rank_leave_a_checkpoint_that_resumes(sliding, tmp_path):
    """--max-wall-time, then SIGTERM to the launcher (a batch system's stop): every rank ends with
    75 and a checkpoint. Then a rank killed (SIGKILL) mid-run: every rank exits and the newest
    checkpoint verifies. The run resumes on one rank to one rank's end, bitwise. (The 2-rank
    steps take about 1.8 s here: the wall-time budget, counted from the first step, is 0.2 s, so
    that the run stops, and the resumes that follow have steps left, on a machine 9 x faster.)"""
    shutil.copy(sliding / "case.toml", tmp_path / "case.toml")
    stopped = sphere("run", "case.toml", "-o", "run", "-q", "--max-wall-time", "0.2", ranks=2, cwd=tmp_path)
    assert stopped.returncode == 75, stopped.stderr
    first = newest_valid_checkpoint(tmp_path / "run" / "checkpoints")
    assert first is not None and first.step > 0

    env = {**os.environ, **RANK_ENV}
    command = [str(MPIEXEC), "-n", "2", sys.executable, "-m", "sphere_cli", "resume", "run", "-q"]
    log = tmp_path / "run" / "run.log"

    def resumed(launches: int) -> tuple[subprocess.Popen, list[int]]:
        """A 2-rank resume under way, past its first step, and its ranks' process ids."""
        launcher = subprocess.Popen(command, cwd=tmp_path, env=env, stderr=subprocess.PIPE, text=True)
        _wait_for(lambda: _pids(log, launches), launcher)
        start = newest_valid_checkpoint(tmp_path / "run" / "checkpoints").step
        _wait_for(lambda: _status(tmp_path).get("step", 0) > start, launcher)
        return launcher, _pids(log, launches)

    launcher, _ = resumed(2)
    launcher.send_signal(signal.SIGTERM)
    _, err = launcher.communicate(timeout=120)
    assert launcher.returncode == 75, err
    assert "Traceback" not in err
    second = newest_valid_checkpoint(tmp_path / "run" / "checkpoints")
    assert second.step > first.step

    launcher, pids = resumed(3)
    os.kill(pids[1], signal.SIGKILL)
    launcher.communicate(timeout=120)
    assert launcher.returncode != 0
    deadline = time.monotonic() + 60
    while any(Path(f"/proc/{pid}").exists() for pid in pids):  # no rank outlives the killed one
        assert time.monotonic() < deadline
        time.sleep(0.05)
    assert newest_valid_checkpoint(tmp_path / "run" / "checkpoints").step >= second.step
    run_ok(sphere("resume", "run", "-q", cwd=tmp_path))
    final = list_checkpoints(tmp_path / "run" / "checkpoints")[-1]
    assert_bitwise(sliding / "one" / "checkpoints" / final.name, final)


def _status(root: Path) -> dict:
    try:
        return json.loads((root / "run" / "status.json").read_text())
    except (OSError, ValueError):
        return {}


def test_a_particle_gone_bad_on_a_rank_stops_every_rank_as_one_rank_stops(tmp_path):
    """The bed thrown upwards out of its open top: the stability check, run on every rank,
    stops the run with exit 70 and one rank's message (the same step, particle, position and
    velocity), status.json says failed, and the newest checkpoint verifies."""
    (tmp_path / "case.toml").write_text(
        SETTLING.replace("velocity = [0.0, 0.0, -0.3]", "velocity = [0.0, 0.0, 3.0]")
    )
    one = sphere("run", "case.toml", "-o", "one", "-q", cwd=tmp_path)
    two = sphere("run", "case.toml", "-o", "two", "-q", ranks=2, cwd=tmp_path)
    for result in (one, two):
        assert result.returncode == 70, result.stderr
        assert "left the box through an open face" in result.stderr and "Traceback" not in result.stderr
    errors = [line for line in two.stderr.splitlines() if line.startswith("sphere: error:")]
    assert errors == [line for line in one.stderr.splitlines() if line.startswith("sphere: error:")]
    assert json.loads((tmp_path / "two" / "status.json").read_text())["state"] == "failed"
    assert newest_valid_checkpoint(tmp_path / "two" / "checkpoints") is not None


# 8 light beads (10 kg/m^3) at rest in a 4 m/s stream of water (the VANS case of
# test_vans1d_bad_input.py): the drag relaxes them in 4.8 us, under dt = 15 us, so the fluid's
# check fails at the first step while no bead yet moves half its radius in a step (the motion's
# check passes there, and fails a step later)
UNSTABLE_DRAG = VANS_CASE
for _old, _new in (
    (
        'duration = 0.0002\ndt = "auto"',
        'duration = 0.003\ndt = 1.5e-5\nstability = "contact"\nblowup_check_every = 1',
    ),
    ("density = 2500.0", "density = 10.0"),
    ("normal_stiffness = 1.0e4", "normal_stiffness = 10.0"),
    (
        'flow = { kind = "solved", mixing_length = "li-sawamoto" }',
        'flow = { kind = "profile", z = [0.0, 0.008], u = [4.0, 4.0] }',
    ),
):
    assert UNSTABLE_DRAG.count(_old) == 1, _old
    UNSTABLE_DRAG = UNSTABLE_DRAG.replace(_old, _new)


def test_a_fluid_gone_bad_on_the_ranks_stops_the_run_as_on_one_rank(tmp_path):
    """Each rank runs the fluid's own check on its particles between outputs (the state is not
    gathered for it): the unstable drag is named at the same step as on one rank, not left to
    the motion's check a step later."""
    (tmp_path / "case.toml").write_text(UNSTABLE_DRAG)
    one = sphere("run", "case.toml", "-o", "one", "-q", cwd=tmp_path)
    two = sphere("run", "case.toml", "-o", "two", "-q", ranks=2, cwd=tmp_path)
    errors = []
    for result in (one, two):
        assert result.returncode == 70, result.stderr
        assert "at step 1 " in result.stderr and "drag relaxation time" in result.stderr, result.stderr
        errors.append([line for line in result.stderr.splitlines() if line.startswith("sphere: error:")])
    assert errors[0] == errors[1]


def test_a_fluid_step_failing_on_every_rank_is_reported_once_as_on_one_rank(tmp_path):
    """tests/cli/test_fluid_moving_grid_input.py's wall squeezing the Darcy cells below a
    particle: every rank's pore-pressure step meets it at the same step; rank 0 reports it as
    one rank does (exit 70, the same error line on stderr and in run.log, status.json failed at
    the same step and time with the same error and exit code, no longer "building"), and the
    others leave the report to it."""
    (tmp_path / "case.toml").write_text(edit(DARCY_FOLLOWING, "[fluid]", DARCY_TOP_WALL))
    runs = {
        ranks: sphere("run", "case.toml", "-o", f"on{ranks}", "-q", ranks=ranks, cwd=tmp_path)
        for ranks in (1, 2)
    }
    reported = []
    for ranks, result in runs.items():
        assert result.returncode == 70, result.stderr
        assert result.stderr.count("the fluid cells (fluid.grid.follow_top_wall, 8 along z)") == 1, (
            result.stderr
        )
        status = json.loads((tmp_path / f"on{ranks}" / "status.json").read_text())
        errors = [line for line in result.stderr.splitlines() if line.startswith("sphere: error:")]
        logged = [
            line.split(" ERROR ", 1)[1]
            for line in (tmp_path / f"on{ranks}" / "run.log").read_text().splitlines()
            if " ERROR " in line
        ]
        reported.append(
            (
                errors,
                logged,
                {key: status.get(key) for key in ("state", "step", "time", "error", "activity", "exit_code")},
            )
        )
    assert reported[0] == reported[1] and reported[0][2]["step"] > 0, reported


# A lead that sends a command no follower knows, or fails itself, inside a collective step; argv:
# the run directory, and which rank fails
FAILING_RANK = """
import sys
from pathlib import Path

from sphere_cli import ranks
from sphere_cli.io.rundir import RunDirectory

world = ranks.start()
if not world.leads:
    sys.exit(world.follow())
rundir = RunDirectory(Path(sys.argv[1]))
rundir.write_status({"state": "running", "step": 40, "time": 0.004})
world.record_failures_in(rundir.path.resolve())
if sys.argv[2] == "follower":
    world.order("no such command")
    world.together(world.comm.Barrier)
else:
    world.together(lambda: 1 / 0)
"""


@pytest.mark.parametrize(
    ("failing", "message"),
    [
        ("follower", "sphere: error: rank 1: AttributeError"),
        ("lead", "sphere: error: rank 0, during the steps: ZeroDivisionError"),
    ],
)
def test_a_rank_that_fails_alone_records_its_error_before_every_rank_ends(tmp_path, failing, message):
    """An error only one rank sees (a bug, memory) ends every rank with exit 70, and the run
    directory says so as a one-rank run's would: the message in run.log, status.json failed with
    the run's progress kept and the exit code (sphere sweep reads them)."""
    (tmp_path / "script.py").write_text(FAILING_RANK)
    (tmp_path / "run").mkdir()
    env = {**os.environ, "NUMBA_NUM_THREADS": "1"}
    command = [str(MPIEXEC), "-n", "2", sys.executable, "script.py", "run", failing]
    result = subprocess.run(command, cwd=tmp_path, capture_output=True, text=True, timeout=120, env=env)
    assert result.returncode == 70, result.stdout + result.stderr
    assert result.stderr.count(message) == 1, result.stderr
    log = (tmp_path / "run" / "run.log").read_text()
    assert f"ERROR {message}" in log, log
    status = json.loads((tmp_path / "run" / "status.json").read_text())
    assert status["state"] == "failed" and status["error"].startswith(message), status
    assert status["step"] == 40 and status["ranks"] == 2 and status["exit_code"] == 70


def test_what_does_not_run_split_is_refused_by_name(tmp_path):
    """A fluid without particles is not split across ranks: refused with exit 2 by the lead,
    once, naming it, with nothing written; more ranks than cells along the box's widest axis
    too."""
    alone = "[simulation]\nduration = 0.01\ndt = 0.001\n\n[domain]\nupper = [0.01, 0.01, 0.02]\n\n[fluid]\n"
    (tmp_path / "alone.toml").write_text(
        alone
        + 'model = "darcy"\ngrid = { cells = [1, 1, 8] }\n'
        + 'permeability = { model = "constant", value = 1e-10 }'
    )
    result = sphere("run", "alone.toml", "-o", "out", ranks=2, cwd=tmp_path)
    assert result.returncode == 2 and "no particles (a fluid-only case)" in result.stderr, result.stderr
    assert result.stderr.count("sphere: error: started as 2 MPI ranks") == 1, result.stderr
    assert "Traceback" not in result.stderr
    assert not (tmp_path / "out").exists()
    (tmp_path / "narrow.toml").write_text(
        SETTLING.replace("[0.016, 0.006, 0.012]", "[0.004, 0.004, 0.004]")
        .replace("[0.016, 0.006, 0.009]", "[0.004, 0.004, 0.004]")
        .replace("count = 200", "count = 5")
    )
    result = sphere("run", "narrow.toml", "-o", "out", ranks=3, cwd=tmp_path)
    assert result.returncode == 2 and "use at most" in result.stderr, result.stderr
    assert not (tmp_path / "out").exists()
