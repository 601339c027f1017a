"""`sphere validate` resolves the time step as `sphere run` does, from the particles, walls and
fluid built as the run builds them (scene/builder.py check_build), so a dt the run refuses at
its start is refused before a batch job is queued, with the same message; and a random placement
that cannot be done is found by doing it. (The fluid's coupling and initial fields, also checked
there, are tested beside their run's refusals: tests/cli/test_darcy_bad_input.py,
test_fluid_navier_stokes_input.py.)"""

from __future__ import annotations

import pytest
from cli_test_support import FROM_FILE, TINY, assert_clean_error, edit, line_of, sphere_inproc
from test_validate_fluid_rules import FIXED_BED

GIVEN_DT = edit(TINY, 'dt = "auto"', "dt = 1e-6")
LIGHT_LID = (
    '[[walls]]\nface = "z-"\n\n[[walls]]\nface = "z+"\nmode = "stress"\nstress = 1000.0\nmass = 1e-9\n'
)
FAST_LID = '[[walls]]\nface = "z-"\n\n[[walls]]\nface = "z+"\nmode = "velocity"\nvelocity = -10.0\n'
LONG_FIXED_BED = edit(FIXED_BED, "duration = 0.001", "duration = 1000.0")

CASES = [
    # (id, case, dt refused, a dt below its limit, fragments of the message): TINY's lightest pair
    # allows 1.4e-5 s alone, 1.4e-6 s held by 12 contacts at once (simulation.stability =
    # "packing"); the fixed bed's 2.5 mm cells with nu = 1e-6 m^2/s, dx^2/(8 nu) = 3.125 s
    ("above-one-contact", GIVEN_DT, "1e-3", "1e-6", ["above the stability limit 1.406e-05 s"]),
    ("above-the-packing-bound", GIVEN_DT, "5e-6", "1e-6", ["above the stability bound 1.399e-06 s"]),
    (
        "above-a-light-stress-driven-wall",
        edit(GIVEN_DT, '[[walls]]\nface = "z-"\n', LIGHT_LID),
        "1e-6",
        "1e-7",
        ["stress-driven z+ wall (walls[1]): mass 1e-09 kg"],
    ),
    (
        "longer-than-a-fast-wall-allows",
        edit(GIVEN_DT, '[[walls]]\nface = "z-"\n', FAST_LID),
        "1e-5",
        "1e-6",
        ["walls[1].velocity = -10 m/s, covers 0.1 of the smallest radius"],
    ),
    (
        "above-the-fluid-alone",
        LONG_FIXED_BED,
        "100.0",
        "1.0",
        ["above the stability limit 3.125 s (viscous diffusion"],
    ),
]


def _with_dt(case: str, dt: str) -> str:
    return "\n".join("dt = " + dt if line.startswith("dt = ") else line for line in case.splitlines()) + "\n"


@pytest.mark.parametrize("command", ["validate", "run"])
@pytest.mark.parametrize(
    ("case", "dt", "fragments"), [(c[1], c[2], c[4]) for c in CASES], ids=[c[0] for c in CASES]
)
def test_a_time_step_the_run_refuses_is_refused_by_validate(tmp_path, command, case, dt, fragments):
    """Each dt is refused by both commands with one message naming simulation.dt and its line,
    exit 65, nothing written."""
    case = _with_dt(case, dt)
    (tmp_path / "case.toml").write_text(case)
    args = ("validate", "case.toml") if command == "validate" else ("run", "case.toml", "-o", "out", "-q")
    result = sphere_inproc(*args, cwd=tmp_path)
    where = f"case.toml:{line_of(case, 'dt =')}: simulation.dt = "
    assert_clean_error(result, 65, where, *fragments)
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize(("case", "dt"), [(c[1], c[3]) for c in CASES], ids=[c[0] for c in CASES])
def test_below_the_limit_the_same_cases_are_valid(tmp_path, case, dt):
    """The refusals above are the time step's: below its limit each case is valid."""
    (tmp_path / "case.toml").write_text(_with_dt(case, dt))
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert result.code == 0, result.stderr


def test_a_random_placement_that_cannot_be_done_is_refused_by_validate(tmp_path):
    """200 spheres in TINY's box pass the capacity check (they fill under half the region) but
    random insertion places 118: validate now places them as the run does and refuses it."""
    case = edit(TINY, 'placement = { method = "lattice" }', 'placement = { method = "random" }')
    case = edit(case, "count = 20", "count = 200")
    (tmp_path / "case.toml").write_text(case)
    result = sphere_inproc("validate", "case.toml", cwd=tmp_path)
    assert_clean_error(result, 65, "particles.placement", "random insertion placed only 118 of 200")
    (tmp_path / "case.toml").write_text(edit(case, "count = 200", "count = 100"))
    assert sphere_inproc("validate", "case.toml", cwd=tmp_path).code == 0


def test_a_sweep_member_with_a_time_step_above_its_limit_is_refused(tmp_path):
    """A sweep over the stiffness at a given dt: the stiffer member's dt is above its limit, so
    `sphere sweep` refuses before writing any member (a job array would fail on that member)."""
    (tmp_path / "case.toml").write_text(GIVEN_DT)
    result = sphere_inproc(
        "sweep", "case.toml", "--vary", "contact.normal_stiffness=1e4,1e7", "-o", "sw", cwd=tmp_path
    )
    assert_clean_error(result, 65, "sweep member", "contact.normal_stiffness = 10000000.0", "simulation.dt")
    assert not (tmp_path / "sw").exists()


@pytest.mark.parametrize("command", ["validate", "run"])
def test_overlapping_particles_of_a_placement_file_are_refused_by_validate(tmp_path, command):
    """A file whose r column holds diameters (a classic of files exported from other codes):
    spheres 4 mm apart with r = 3 mm overlap by 2/3 of a radius. `run` refused it at its build
    (from the neighbour list); `validate` now finds it too, without compiling the list's kernels
    (scene/packing.py worst_overlap_of), with the same message."""
    (tmp_path / "case.toml").write_text(
        FROM_FILE.replace("upper = [0.01, 0.01, 0.01]", "upper = [0.02, 0.01, 0.01]")
    )
    (tmp_path / "spheres.csv").write_text("x,y,z,r\n0.006,0.005,0.005,0.003\n0.010,0.005,0.005,0.003\n")
    args = ("validate", "case.toml") if command == "validate" else ("run", "case.toml", "-o", "out", "-q")
    result = sphere_inproc(*args, cwd=tmp_path)
    assert_clean_error(
        result,
        65,
        "particles.overlap_tolerance",
        "particles 0 and 1 (from spheres.csv) start overlapping by 0.667",
    )
    assert not (tmp_path / "out").exists()


@pytest.mark.parametrize("command", ["validate", "run"])
def test_a_box_the_gpu_cannot_search_is_refused_by_validate(tmp_path, command):
    """TINY's 20 spheres in a box of 0.5 m: 12 167 000 search cells, which the CPU lists sparsely
    and the GPU's search would store whole. run refused it at its build (before looking for a
    GPU: physics/device_steps.py); validate, on a login node without a GPU, now does too."""
    case = edit(TINY, "upper = [0.01, 0.01, 0.02]", "upper = [0.5, 0.5, 0.5]")
    (tmp_path / "case.toml").write_text(edit(case, 'dt = "auto"', 'dt = "auto"\ndevice = "cuda"'))
    args = ("validate", "case.toml") if command == "validate" else ("run", "case.toml", "-o", "out", "-q")
    result = sphere_inproc(*args, cwd=tmp_path)
    assert_clean_error(result, 65, 'simulation.device = "cuda": the box holds 12167000 search cells for 20')
    assert not (tmp_path / "out").exists()
    (tmp_path / "case.toml").write_text(case)  # on the CPU: valid
    assert sphere_inproc("validate", "case.toml", cwd=tmp_path).code == 0
