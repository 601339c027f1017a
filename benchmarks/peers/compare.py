"""Time sphere against LIGGGHTS and LAMMPS on the settled canonical bed, in alternating rounds
(this machine's speed drifts by tens of per cent between minutes: only rounds taken side by side
compare). sphere's settled bed (sphere_cli/bench/dem.py) is written as a LAMMPS data file; each
peer reads it, runs WARMUP steps (it starts with no contact history), then the timed steps, with
the input scripts of this folder: the same contact law, walls, gravity, dt and neighbour skin.
A peer that is not installed is skipped, saying so (`make bench-peers` installs Debian's
`liggghts`, `lammps` and `openmpi-bin` where it can).

    python benchmarks/peers/compare.py [N] [steps per round] [rounds] [threads ...]

Each thread count T compares sphere on T threads with each peer on T MPI ranks; for T > 1,
sphere on T MPI ranks of one thread (`sphere bench ranks`' member, the mpich wheel's mpiexec)
runs in the same rounds too ("sphere ranks"). Prints the particle-steps per second of each code
and the ratios sphere / peer, round by round, with their median and range; writes them to
bench-results/peers-N.json."""

import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

from sphere_cli.bench import machine
from sphere_cli.bench.dem import settled_scene
from sphere_cli.bench.ranks import mpiexec, time_on_ranks
from sphere_cli.kernels.laws import D_N, D_T, K_N, K_T, MU
from sphere_cli.simulation import advance

HERE = Path(__file__).resolve().parent
WARMUP = 200
PEERS = {"LIGGGHTS": ("liggghts", HERE / "in.liggghts"), "LAMMPS": ("lmp", HERE / "in.lammps")}
LOOP = re.compile(r"Loop time of ([0-9.eE+-]+) on (\d+) procs for (\d+) steps with (\d+) atoms")


def write_data(scene, path: Path) -> dict:
    """The bed as a LAMMPS data file (atom style sphere: id type diameter density x y z, and the
    velocities), and the scene's parameters as the input scripts' variables."""
    st = scene.state
    p, box, walls = st.particles, st.box, st.walls
    assert not box.periodic.any() and np.ptp(p.radius) == 0 and np.ptp(p.mass) == 0
    assert np.allclose(box.lower, 0.0) and walls.axis.size == 6 and not walls.vel.any()
    r, m = float(p.radius[0]), float(p.mass[0])
    density = m / (4.0 / 3.0 * math.pi * r**3)
    n = p.count
    lines = ["sphere's settled canonical bed", "", f"{n} atoms", "2 atom types", ""]
    lines += [f"0.0 {float(box.upper[a])!r} {lo}lo {lo}hi" for a, lo in enumerate("xyz")]
    lines += ["", "Atoms # sphere", ""]
    atoms = enumerate(p.pos.tolist())
    lines += [f"{i + 1} 1 {2 * r!r} {density!r} {x!r} {y!r} {z!r}" for i, (x, y, z) in atoms]
    lines += ["", "Velocities", ""]
    vel = np.hstack([p.vel, p.angvel]).tolist()
    lines += [f"{i + 1} " + " ".join(map(repr, v)) for i, v in enumerate(vel)]
    path.write_text("\n".join(lines) + "\n")
    pair, wall = scene.contact.table[0, 0], walls.table[0, 0]
    # sphere's dashpot coefficients are D sqrt(m*): m* = m/2 between two spheres, m at a wall
    cn, ct = pair[D_N] * math.sqrt(m / 2), pair[D_T] * math.sqrt(m / 2)
    cnw, ctw = wall[D_N] * math.sqrt(m), wall[D_T] * math.sqrt(m)
    assert wall[K_N] == pair[K_N] and wall[K_T] == pair[K_T] and wall[MU] == pair[MU]
    values = {
        "data": str(path), "skin": st.neighbors.skin, "dt": st.clock.dt,
        "g": float(np.linalg.norm(box.body_acc)), "lx": box.upper[0], "ly": box.upper[1], "lz": box.upper[2],
        "kn": pair[K_N], "kt": pair[K_T], "mu": pair[MU], "cn": cn, "ct": ct, "cnw": cnw, "ctw": ctw,
        "gn": cn / (m / 2), "gt": ct / (m / 2), "gnw": cnw / m, "gtw": ctw / m,
    }  # fmt: skip
    return {key: float(v) if isinstance(v, np.floating) else v for key, v in values.items()}


def open_mpi_launcher() -> str | None:
    """The first mpirun on PATH that is Open MPI's: Debian's peers are built against it (an
    activated sphere environment puts the mpich wheel's mpirun first, which cannot start them)."""
    for folder in os.environ.get("PATH", "").split(os.pathsep):
        candidate = Path(folder) / "mpirun"
        if candidate.is_file() and os.access(candidate, os.X_OK):
            version = subprocess.run([str(candidate), "--version"], capture_output=True, text=True)
            if "Open MPI" in version.stdout + version.stderr:
                return str(candidate)
    return None


MPIRUN = open_mpi_launcher()


def run_peer(program: str, script: Path, variables: dict, ranks: int, workdir: Path) -> tuple[float, str]:
    """One run of a peer; returns the seconds of its timed loop and its last thermo line."""
    command = [program, "-in", str(script), "-log", "none"]
    for key, value in variables.items():
        command += ["-var", key, repr(value) if isinstance(value, float) else str(value)]
    env = dict(os.environ)
    if ranks > 1:
        command = [MPIRUN, "--oversubscribe", "-np", str(ranks)] + command
        env.update(OMPI_ALLOW_RUN_AS_ROOT="1", OMPI_ALLOW_RUN_AS_ROOT_CONFIRM="1")
    out = subprocess.run(command, cwd=workdir, env=env, capture_output=True, text=True)
    loops = LOOP.findall(out.stdout)
    if out.returncode != 0 or len(loops) != 2:
        sys.exit(f"{program} failed (exit {out.returncode}):\n{out.stdout[-3000:]}\n{out.stderr[-2000:]}")
    seconds, procs, steps, atoms = loops[-1]
    assert int(procs) == ranks and int(steps) == variables["steps"]
    # the last thermo line before the loop summary: step, atoms, kinetic energy
    thermo = [ln.split() for ln in out.stdout.splitlines() if re.fullmatch(r"\s*\d+\s+\d+\s+\S+\s*", ln)]
    return float(seconds), thermo[-1]


def main(n: int, steps: int, rounds: int, threads: list[int]) -> dict:
    scene = settled_scene(n, print)
    p = scene.state.particles
    workdir = Path(tempfile.mkdtemp(prefix="sphere-peers-"))
    variables = write_data(scene, workdir / "bed.data") | {"warmup": WARMUP, "steps": steps}
    peers = {}
    for name, (program, script) in PEERS.items():
        path = shutil.which(program)
        if path is None:
            print(f"{name} is not installed ({program} not on PATH): skipped")
        else:
            peers[name] = (path, script)
    if any(t > 1 for t in threads) and MPIRUN is None:
        print("Open MPI's mpirun is not on PATH: the peers run on one rank only")
        threads = [1]
    # a bed at rest: the kinetic energy a peer may end with, per particle (m g d / 100)
    ke_limit = n * float(p.mass[0]) * 9.81 * 2 * float(p.radius[0]) / 100
    results = {"machine": machine(), "n": n, "steps": steps, "warmup": WARMUP, "rows": []}
    for t in threads:
        numba.set_num_threads(t)
        advance(scene, 5)
        ours = ["sphere"] + (["sphere ranks"] if t > 1 else [])
        rates = {name: [] for name in ours} | {name: [] for name in peers}
        for _ in range(rounds):
            t0 = time.perf_counter()
            advance(scene, steps)
            rates["sphere"].append(n * steps / (time.perf_counter() - t0))
            if t > 1:
                timing = time_on_ranks(mpiexec(), t, n, steps, 1)
                rates["sphere ranks"].append(n * steps / timing["seconds"][0])
            for name, (program, script) in peers.items():
                seconds, thermo = run_peer(program, script, variables, t, workdir)
                if int(thermo[1]) != n or not float(thermo[2]) < ke_limit:
                    sys.exit(f"{name} lost particles or the bed did not stay at rest: {thermo}")
                rates[name].append(n * steps / seconds)
        for name, r in rates.items():
            print(f"N = {n}, {t} thread(s)/rank(s), {name:12s}: median {np.median(r) / 1e6:.2f} M, "
                  f"best {max(r) / 1e6:.2f} M particle-steps/s ({rounds} x {steps} steps)")  # fmt: skip
        row = {"threads": t, "rates": rates, "ratios": {}}
        for ours_name in ours:
            for name in peers:
                ratio = np.array(rates[ours_name]) / np.array(rates[name])
                row["ratios"][f"{ours_name} / {name}"] = ratio.tolist()
                print(f"N = {n}, {t} thread(s)/rank(s): {ours_name} / {name}, round by round: median "
                      f"{np.median(ratio):.2f} (min {ratio.min():.2f}, max {ratio.max():.2f})")  # fmt: skip
        results["rows"].append(row)
    out = Path("bench-results")
    out.mkdir(exist_ok=True)
    (out / f"peers-{n}.json").write_text(json.dumps(results, indent=2))
    shutil.rmtree(workdir)
    return results


if __name__ == "__main__":
    args = [int(v) for v in sys.argv[1:]]
    n, steps, rounds = (args + [10000, 1000, 5][len(args) :])[:3]
    main(n, steps, rounds, args[3:] or [1, 2])
