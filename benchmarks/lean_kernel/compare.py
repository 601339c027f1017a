"""Time sphere against the lean C kernel of lean.c on the settled canonical bed, in alternating
rounds (this machine's speed drifts by tens of per cent between minutes: only rounds taken side
by side compare). Both advance the same checkpoint with sphere's own neighbour search; the lean
kernel replaces the motion, contact and wall kernels only. Before timing, both trajectories must
agree to round-off (the kernels sum the forces in different orders).

    python benchmarks/lean_kernel/compare.py [N] [steps per round] [rounds]

Needs gcc; one thread each (sphere's bench times two threads too)."""

import ctypes
import math
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numba
import numpy as np

from sphere_cli.bench.dem import settled_scene
from sphere_cli.kernels.laws import D_N, D_T, K_N, K_T, LINEAR, MU
from sphere_cli.physics.module import Module
from sphere_cli.simulation import advance

HERE = Path(__file__).resolve().parent
P, D, N64 = ctypes.c_void_p, ctypes.c_double, ctypes.c_int64


def load_library() -> ctypes.CDLL:
    lib_path = Path(tempfile.mkdtemp()) / "liblean.so"
    flags = ["-O3", "-march=native", "-shared", "-fPIC"]
    subprocess.run(["gcc", *flags, str(HERE / "lean.c"), "-o", str(lib_path), "-lm"], check=True)
    lib = ctypes.CDLL(str(lib_path))
    lib.lean_kick_drift.restype = D
    lib.lean_kick_drift.argtypes = [N64] + [P] * 8 + [D, D, D]
    lib.lean_kick.argtypes = [N64] + [P] * 4 + [D, D, D]
    lib.lean_forces.argtypes = [N64, N64] + [P] * 9 + [N64] + [P] * 4 + [D, D, P, P, P, D, P, P]
    return lib


def address(a: np.ndarray) -> int:
    assert a.flags.c_contiguous
    return a.ctypes.data


class LeanKernel(Module):
    """Stands in for the scene's Motion, PairContactForces and PlaneWallForces: one module of the
    step (physics/module.py) with their kick_drift, forces and kick."""

    name = "particles"

    def __init__(self, lib, scene):
        st = scene.state
        p = st.particles
        walls = st.walls
        assert np.ptp(p.radius) == 0 and np.ptp(p.mass) == 0 and not st.box.periodic.any()
        contact = scene.contact
        assert contact.law_code == LINEAR and not contact.rolling and contact.table.shape[0] == 1
        assert (walls.table == walls.table[0]).all() and not walls.vel.any()
        self.lib, self.r, self.m = lib, float(p.radius[0]), float(p.mass[0])
        self.inv_m, self.inv_i = float(p.inv_mass[0]), float(p.inv_inertia[0])
        pair, wall = scene.contact.table[0, 0], walls.table[0, 0]
        # the dashpot coefficients of the table take sqrt(m*): m/2 between two spheres, m at a wall
        self.pair = np.array([pair[K_N], pair[K_T], pair[D_N], pair[D_T], pair[MU]])
        self.pair[2:4] *= math.sqrt(self.m / 2)
        self.wall = np.array([wall[K_N], wall[K_T], wall[D_N], wall[D_T], wall[MU]])
        self.wall[2:4] *= math.sqrt(self.m)
        self.gravity = np.ascontiguousarray(st.box.body_acc, dtype=float)

    def kick_drift(self, state):
        p, nl = state.particles, state.neighbors
        arrays = (p.pos, p.vel, p.angvel, p.vel_pred, p.angvel_pred, p.force, p.torque, nl.ref_pos)
        nl.moved2 = self.lib.lean_kick_drift(
            p.count, *map(address, arrays), state.clock.dt, self.inv_m, self.inv_i
        )

    def forces(self, state):
        p, nl, w = state.particles, state.neighbors, state.walls
        motion = (p.pos, p.vel, p.angvel, p.vel_pred, p.angvel_pred)
        self.lib.lean_forces(
            p.count, nl.nbr.shape[1],
            *map(address, motion + (nl.nbr, nl.nbr_count, nl.start, nl.hist)),
            w.axis.size, *map(address, (w.axis, w.sign, w.coord, w.hist)),
            self.r, self.m, address(self.gravity), address(self.pair), address(self.wall), state.clock.dt,
            address(p.force), address(p.torque),
        )  # fmt: skip

    def kick(self, state):
        p = state.particles
        arrays = (p.vel, p.angvel, p.force, p.torque)
        self.lib.lean_kick(p.count, *map(address, arrays), state.clock.dt, self.inv_m, self.inv_i)


def main(n: int, steps: int, rounds: int) -> None:
    numba.set_num_threads(1)
    ours = settled_scene(n, print)
    lean = settled_scene(n, print)
    kernel = LeanKernel(load_library(), lean)
    lean.motion, lean.contact = kernel, None
    lean.walls = None  # the lean kernel does the walls itself
    lean.order_modules()  # the step's hooks are the kernel's
    advance(ours, 20)
    advance(lean, 20)
    a, b = ours.state.particles, lean.state.particles
    off = np.abs(a.pos - b.pos).max() / a.radius[0]
    dv = np.abs(a.vel - b.vel).max()
    print(f"after 20 steps: max |x_sphere - x_lean| = {off:.1e} R, max |v| difference {dv:.1e} m/s")
    if not off < 1e-9:
        sys.exit("the lean kernel does not reproduce sphere's trajectory: no timing")
    rates = {"sphere": [], "lean C": []}
    for _ in range(rounds):
        for name, scene in (("sphere", ours), ("lean C", lean)):
            t0 = time.perf_counter()
            advance(scene, steps)
            rates[name].append(n * steps / (time.perf_counter() - t0) / 1e6)
    for name, r in rates.items():
        rate = f"median {np.median(r):.2f}, best {max(r):.2f} M particle-steps/s"
        print(f"{name:7s} N = {n}: {rate} ({rounds} x {steps} steps)")
    ratio = np.array(rates["sphere"]) / np.array(rates["lean C"])
    spread = f"min {ratio.min():.2f}, max {ratio.max():.2f}"
    print(f"sphere / lean C, round by round: median {np.median(ratio):.2f} ({spread})")


if __name__ == "__main__":
    args = [int(v) for v in sys.argv[1:]]
    main(*(args + [10000, 200, 9][len(args) :]))
