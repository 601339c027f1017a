"""A run whose OpenMP threads would share their cores with other busy processes
(sphere_cli/runtime.py): when its threads are made to wait passively and when it is warned
instead, how the busy cores are counted, and that a real busy process is seen."""

from __future__ import annotations

import os
import subprocess
import sys
import threading
import time
from types import SimpleNamespace

import pytest

from sphere_cli import runtime
from sphere_cli.runtime import busy_cores, measure_busy_cores, shared_cores_note, start_threads

# first lines of /proc/stat: user nice system idle iowait irq softirq steal guest guest_nice
LINE = "cpu  {user} 0 {system} {idle} {iowait} 0 {softirq} {steal} 0 0\nintr 1 2 3\n"


def stat(user=0, system=0, idle=0, iowait=0, softirq=0, steal=0) -> str:
    return LINE.format(user=user, system=system, idle=idle, iowait=iowait, softirq=softirq, steal=steal)


def test_busy_cores_counts_user_system_and_interrupts_only():
    cores = os.cpu_count() or 1
    before = stat(100, 50, 1000, 10, 5, 7)
    # 40 + 20 + 10 of 200 ticks busy; idle 100, iowait 20 and steal 10 are not
    after = stat(140, 70, 1100, 30, 15, 17)
    assert busy_cores(before, after) == pytest.approx(cores * 70 / 200)
    assert busy_cores(before, before) == 0.0


@pytest.mark.parametrize(
    "threads, cores, busy, expected",
    [
        (1, 2, 2.0, False),  # one thread never waits for another
        (2, 2, 0.0, False),
        (2, 2, 0.4, False),  # noise, within the margin
        (2, 2, 1.0, True),  # one busy process on one of our two cores
        (2, 4, 2.0, False),  # it leaves two cores free
        (4, 4, 1.0, True),
        (8, 64, 56.0, False),
        (8, 64, 57.0, True),
    ],
)
def test_the_note_is_given_when_busy_processes_leave_fewer_free_cores_than_threads(
    threads, cores, busy, expected
):
    note = shared_cores_note(threads, cores=cores, busy=busy, wait_policy="", layer="default")
    assert (note is not None) is expected
    if expected:
        assert "OMP_WAIT_POLICY=PASSIVE" in note and f"{busy:.1f}" in note and f"{threads} threads" in note


@pytest.mark.parametrize("policy", ["PASSIVE", "passive", " Passive "])
def test_no_note_with_the_passive_wait_policy(policy):
    assert shared_cores_note(2, cores=2, busy=2.0, wait_policy=policy, layer="default") is None
    assert shared_cores_note(2, cores=2, busy=2.0, wait_policy="ACTIVE", layer="default") is not None


@pytest.mark.parametrize(
    "layer, expected", [("workqueue", False), ("tbb", False), ("omp", True), ("default", True)]
)
def test_no_note_for_threading_layers_that_do_not_spin(layer, expected):
    note = shared_cores_note(2, cores=2, busy=2.0, wait_policy="", layer=layer)
    assert (note is not None) is expected


def test_the_sample_is_the_change_over_its_sleep(tmp_path):
    """measure_busy_cores reads the file, sleeps, reads it again: the busy cores of that change."""
    path = tmp_path / "stat"
    path.write_text(stat(100, 50, 1000, 10, 5, 7))
    later = threading.Timer(0.05, path.write_text, [stat(140, 70, 1100, 30, 15, 17)])
    later.start()
    busy = measure_busy_cores(0.5, str(path))
    later.join()
    assert busy == pytest.approx((os.cpu_count() or 1) * 70 / 200)
    assert measure_busy_cores(0.01, str(tmp_path / "absent")) is None


@pytest.mark.skipif(not os.path.exists("/proc/stat"), reason="reads /proc/stat (Linux)")
def test_a_busy_process_on_every_core_is_seen():
    cores = os.cpu_count() or 1
    spin = "import time\nend = time.time() + 5\nwhile time.time() < end: pass\n"
    children = [subprocess.Popen([sys.executable, "-c", spin]) for _ in range(cores)]
    try:
        time.sleep(0.3)  # let them start
        busy = measure_busy_cores(0.5)
    finally:
        for child in children:
            child.kill()
            child.wait()
    # every core runs one spinning child; the lower bound leaves 40 % to a hypervisor's steal,
    # which is not counted as busy; no core is busier than all the time
    assert busy is not None and 0.6 * cores <= busy <= 1.02 * cores


# a case whose thread count is NUMBA_NUM_THREADS: particles placed from a file (no count)
ALL_THREADS = SimpleNamespace(
    simulation=SimpleNamespace(threads=None), particles=SimpleNamespace(count=None), fluid=None
)


@pytest.fixture
def busy_machine(monkeypatch):
    """Every core kept busy by others, as shared_cores would measure it."""
    monkeypatch.setattr(runtime, "shared_cores", lambda threads, **machine: (2.0, 2))
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    return monkeypatch


def test_threads_not_yet_started_are_made_to_wait_passively(busy_machine, capsys):
    busy_machine.setattr(runtime, "threads_started", lambda: False)
    note = start_threads(ALL_THREADS)
    assert os.environ["OMP_WAIT_POLICY"] == "PASSIVE"  # set before OpenMP reads it
    assert note.startswith("other processes keep 2.0 of this machine's 2 cores busy")
    assert "wait passively (OMP_WAIT_POLICY=PASSIVE)" in note and "OMP_WAIT_POLICY=ACTIVE" in note
    assert capsys.readouterr().err == f"sphere: note: {note}\n"


@pytest.mark.parametrize("chosen, started", [("ACTIVE", False), ("", True)])
def test_a_chosen_policy_or_started_threads_get_the_warning(busy_machine, capsys, chosen, started):
    """The user's OMP_WAIT_POLICY is kept; threads already started (an earlier run in this
    process) no longer read it: either way the run is warned."""
    if chosen:
        busy_machine.setenv("OMP_WAIT_POLICY", chosen)
    busy_machine.setattr(runtime, "threads_started", lambda: started)
    note = start_threads(ALL_THREADS)
    assert os.environ.get("OMP_WAIT_POLICY", "") == chosen
    assert "set OMP_WAIT_POLICY=PASSIVE" in note
    assert capsys.readouterr().err == f"sphere: warning: {note}\n"


def test_free_cores_leave_the_threads_spinning(monkeypatch, capsys):
    monkeypatch.setattr(runtime, "shared_cores", lambda threads, **machine: None)
    monkeypatch.setattr(runtime, "threads_started", lambda: False)
    monkeypatch.delenv("OMP_WAIT_POLICY", raising=False)
    assert start_threads(ALL_THREADS) is None
    assert "OMP_WAIT_POLICY" not in os.environ
    assert capsys.readouterr().err == ""


def test_a_case_run_in_memory_gets_its_threads():
    # simulation.threads of a notebook's or a test's case is honoured, as by `sphere run`
    import numba

    from sphere_cli.api import run_in_memory
    from sphere_cli.bench.dem import canonical_case

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one core: one thread either way")
    before = numba.get_num_threads()
    try:
        text = canonical_case(8).replace("[simulation]\n", "[simulation]\nthreads = 1\n", 1)
        run_in_memory(text, 2)
        assert numba.get_num_threads() == 1
    finally:
        numba.set_num_threads(before)


@pytest.mark.parametrize(
    "count, fluid, threads",
    [
        (10, None, 1),  # a verification case's handful of spheres
        (999, None, 1),
        (1000, None, 2),
        (2600, None, 5),
        (100_000, None, 8),  # capped by NUMBA_NUM_THREADS
        (200, "vans1d", 1),  # the 1D column is no work beside its particles
        (200, "navier-stokes", 1),  # a grid's own step takes its own count (grid_threads)
        (200, "darcy", 1),
        (None, None, 8),  # placed from a file the caller did not count (api._placed counts it)
    ],
)
def test_without_simulation_threads_a_scene_gets_a_thread_per_500_particles(
    monkeypatch, count, fluid, threads
):
    """runtime.run_threads: on two threads a step's parallel regions cost about 18 us more than
    one thread's serial twins, which a small scene's work does not recover (docs/performance.md)."""
    import numba

    from sphere_cli.runtime import PARTICLES_PER_THREAD, run_threads

    monkeypatch.setattr(numba.config, "NUMBA_NUM_THREADS", 8)
    monkeypatch.setenv("OMP_WAIT_POLICY", "ACTIVE")
    monkeypatch.delenv("NUMBA_THREADING_LAYER", raising=False)
    assert PARTICLES_PER_THREAD == 500
    case = SimpleNamespace(
        simulation=SimpleNamespace(threads=None),
        particles=SimpleNamespace(count=count),
        fluid=None if fluid is None else SimpleNamespace(model=fluid),
    )
    assert run_threads(case) == threads
    case.simulation.threads = 3  # the case's own count wins, capped likewise
    assert run_threads(case) == 3
    case.simulation.threads = 12
    assert run_threads(case) == 8


@pytest.mark.parametrize("count, threads", [(1000, 1), (7999, 1), (16_000, 2), (100_000, 8)])
@pytest.mark.parametrize(
    "variable, value", [("OMP_WAIT_POLICY", "passive"), ("NUMBA_THREADING_LAYER", "workqueue")]
)
def test_threads_that_sleep_between_regions_get_more_particles_each(
    monkeypatch, count, threads, variable, value
):
    """Woken at every parallel region (OMP_WAIT_POLICY=PASSIVE, which make test and a run on
    busy cores use; Numba's workqueue layer), two threads cost about 45 us a region on this
    project's 2-core machine: 1 000 spheres stepped 4.4 x slower on two than on one, 6.4 x on two
    of the workqueue's (docs/performance.md, 2026-12-05 night)."""
    import numba

    from sphere_cli.runtime import PASSIVE_PARTICLES_PER_THREAD, run_threads

    monkeypatch.setattr(numba.config, "NUMBA_NUM_THREADS", 8)
    monkeypatch.setenv("OMP_WAIT_POLICY", "ACTIVE")
    monkeypatch.delenv("NUMBA_THREADING_LAYER", raising=False)
    monkeypatch.setenv(variable, value)
    assert PASSIVE_PARTICLES_PER_THREAD == 8000
    case = SimpleNamespace(simulation=SimpleNamespace(threads=None), particles=SimpleNamespace(count=count))
    assert run_threads(case) == threads


@pytest.mark.parametrize(
    "cells, policy, threads",
    [
        (192, "ACTIVE", 1),  # the Darcy grid of configs/seepage-pulses-darcy.toml
        (2047, "ACTIVE", 1),
        (4096, "ACTIVE", 2),
        (65_536, "ACTIVE", 8),  # capped by NUMBA_NUM_THREADS
        (4096, "PASSIVE", 1),
        (65_536, "PASSIVE", 2),
    ],
)
def test_a_fluid_grid_steps_on_a_thread_per_so_many_cells(monkeypatch, cells, policy, threads):
    """runtime.grid_threads: a grid's step starts about a hundred parallel regions (its pressure
    solve's sweeps), each worth its threads from about 1 000 cells on spinning threads and 40 000
    on sleeping ones (docs/performance.md, 2026-12-05 night); a case's own simulation.threads
    leaves the grid on the run's threads (None)."""
    import numba

    from sphere_cli.runtime import grid_threads

    monkeypatch.setattr(numba.config, "NUMBA_NUM_THREADS", 8)
    monkeypatch.setenv("OMP_WAIT_POLICY", policy)
    monkeypatch.delenv("NUMBA_THREADING_LAYER", raising=False)
    case = SimpleNamespace(simulation=SimpleNamespace(threads=None))
    assert grid_threads(case, cells) == threads
    case.simulation.threads = 8
    assert grid_threads(case, cells) is None


def test_on_mpi_ranks_a_grid_takes_at_most_the_ranks_share(monkeypatch):
    import numba

    from sphere_cli.runtime import grid_threads

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one core: one thread either way")
    monkeypatch.setenv("PMI_SIZE", "2")
    monkeypatch.setenv("OMP_WAIT_POLICY", "ACTIVE")
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)  # the rank's share (sphere_cli/ranks.py)
        assert grid_threads(SimpleNamespace(simulation=SimpleNamespace(threads=None)), 10**6) == 1
    finally:
        numba.set_num_threads(before)


def test_the_grid_steps_on_its_threads_and_gives_the_runs_back(monkeypatch):
    """The Navier-Stokes and Darcy models take their grid's step (the step of after_step and of
    every MPI rank's step_on_rank) inside FluidModule.on_its_threads: on the module's
    step_threads, then on the run's count again, even where the step raises."""
    import numba

    from sphere_cli.physics.fluid.darcy import Darcy
    from sphere_cli.physics.fluid.navier_stokes import NavierStokes
    from sphere_cli.physics.fluid_plugin import FluidModule

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one core: one thread either way")
    seen = []

    class Grid:
        step_threads = 2
        on_its_threads = FluidModule.on_its_threads

        def _grid_step(self, *args):
            seen.append(numba.get_num_threads())
            if len(seen) == 3:
                raise RuntimeError("the step failed")

    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)  # the particles' share
        NavierStokes._step(Grid(), None)
        Darcy._step(Grid(), None, None)
        with pytest.raises(RuntimeError):
            NavierStokes._step(Grid(), None)
        assert seen == [2, 2, 2]
        assert numba.get_num_threads() == 1
        unset = Grid()
        unset.step_threads = None  # simulation.threads set: the run's count
        Darcy._step(unset, None, None)
        assert seen[-1] == 1
    finally:
        numba.set_num_threads(before)


def test_a_run_of_a_few_spheres_takes_one_thread(tmp_path):
    """`sphere run` without simulation.threads, where two threads are allowed: the run's
    provenance records the one thread a scene of 8 spheres gets."""
    import subprocess
    import sys

    import h5py

    from sphere_cli.bench.dem import canonical_case

    case = tmp_path / "case.toml"
    case.write_text(canonical_case(8, duration=4e-5))
    env = {**os.environ, "NUMBA_NUM_THREADS": "2"}
    cmd = [sys.executable, "-m", "sphere_cli", "run", str(case), "-o", str(tmp_path / "run"), "-q"]
    subprocess.run(cmd, check=True, env=env, capture_output=True)
    with h5py.File(tmp_path / "run" / "trajectory.h5", "r") as f:
        assert f["sphere/provenance"].attrs["threads"] == 1


def test_a_placement_files_particles_are_counted_before_the_build(tmp_path):
    """scene/packing.py placed_count: the data lines of a CSV (header, blank lines and comments
    left out), the rows of an HDF5 file's 'position'; None where it cannot tell (the build then
    reports the file), so the run keeps every thread."""
    import h5py
    import numpy as np

    from sphere_cli.scene.packing import placed_count

    csv = tmp_path / "bed.csv"
    csv.write_text("x,y,z,r  # a header\n\n0,0,0,1\n# a comment\n1,0,0,1\n2,0,0,1 # the last\n")
    with h5py.File(tmp_path / "bed.h5", "w") as f:
        f["position"] = np.zeros((5, 3))
    with h5py.File(tmp_path / "empty.h5", "w") as f:
        f["radius"] = np.ones(5)
    counts = {
        name: placed_count(SimpleNamespace(path=name), tmp_path)
        for name in ("bed.csv", "bed.h5", "empty.h5", "missing.csv")
    }
    assert counts == {"bed.csv": 3, "bed.h5": 5, "empty.h5": None, "missing.csv": None}
    assert placed_count(SimpleNamespace(path=str(csv)), tmp_path / "elsewhere") == 3  # absolute


def test_a_run_of_a_few_spheres_from_a_file_takes_one_thread(tmp_path):
    """`sphere run` of 8 spheres placed from a CSV file, two threads allowed: one thread, as
    for 8 spheres of a lattice (every thread before the file was counted)."""
    import subprocess
    import sys

    import h5py

    from sphere_cli.bench.dem import canonical_case

    rows = "\n".join(
        f"{0.0016 + 0.0024 * (k % 2)},{0.0016 + 0.0024 * (k // 2 % 2)},{0.002 + 0.0025 * (k // 4)}"
        for k in range(8)
    )
    (tmp_path / "bed.csv").write_text("x,y,z\n" + rows + "\n")
    text = canonical_case(8, duration=4e-5).replace("count = 8\n", "")
    text = text.replace(
        'placement = { method = "lattice", spacing = 1.2, jitter = 1.0 }',
        'placement = { method = "file", path = "bed.csv" }',
    )
    case = tmp_path / "case.toml"
    case.write_text(text)
    env = {**os.environ, "NUMBA_NUM_THREADS": "2"}
    cmd = [sys.executable, "-m", "sphere_cli", "run", str(case), "-o", str(tmp_path / "run"), "-q"]
    subprocess.run(cmd, check=True, env=env, capture_output=True)
    with h5py.File(tmp_path / "run" / "trajectory.h5", "r") as f:
        assert f["sphere/provenance"].attrs["threads"] == 1
        assert f["particles/trajectory/position/value"].shape[1] == 8


def test_on_mpi_ranks_a_case_without_threads_keeps_each_ranks_share(monkeypatch):
    """sphere_cli/ranks.py gives each rank the node's cores divided by its ranks; a case without
    simulation.threads leaves that as it is, one with it sets its own."""
    import numba

    from sphere_cli.runtime import set_threads

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one core: one thread either way")
    monkeypatch.setenv("PMI_SIZE", "2")
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)  # the rank's share
        set_threads(ALL_THREADS)
        assert numba.get_num_threads() == 1
        set_threads(SimpleNamespace(simulation=SimpleNamespace(threads=2)))
        assert numba.get_num_threads() == 2
    finally:
        numba.set_num_threads(before)


def test_a_run_in_a_process_that_goes_on_gives_its_threads_back(tmp_path):
    """api.run sets the run's own threads (one for 8 spheres) and, when it ends, the process's
    count again (a notebook's, a test worker's)."""
    import h5py
    import numba

    from sphere_cli import api
    from sphere_cli.bench.dem import canonical_case

    if numba.config.NUMBA_NUM_THREADS < 2:
        pytest.skip("one core: one thread either way")
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(2)
        case = tmp_path / "case.toml"
        case.write_text(canonical_case(8, duration=4e-5))
        api.run(case, tmp_path / "run")
        assert numba.get_num_threads() == 2
        with h5py.File(tmp_path / "run" / "trajectory.h5", "r") as f:
            assert f["sphere/provenance"].attrs["threads"] == 1
    finally:
        numba.set_num_threads(before)
