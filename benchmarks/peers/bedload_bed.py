"""Makes configs/bedload-yade-bed.csv, the bed of configs/bedload-yade.toml: the scene of YADE's
two-way coupled bedload example (HydroForceEngine, 1D RANS), in its 10 x 10 d laterally periodic
cell. d = 6 mm; 100 fixed spheres, one per d x d square, their centres at a uniformly random
height within +-d/2 of z = d/2 (YADE's ground; the fluid bottom is z = 0, where the lowest
centres may lie); over them the 1165 mobile spheres of 10 layers
at a solid fraction of 0.61, rained from a jittered lattice and left to settle in still water
under the tilted gravity with sphere's own contact law of that case.

    python benchmarks/peers/bedload_bed.py [run directory]

The deposition is a normal sphere run (default runs/bedload-yade-deposition); the bed is its last
frame with a `fixed` column."""

import math
import sys
from pathlib import Path

import h5py
import numpy as np

from sphere_cli import api

ROOT = Path(__file__).resolve().parents[2]
D = 6e-3
SIDE = 10  # the cell is SIDE x SIDE diameters
MOBILE = 1165  # int(10 layers * 0.61 * d * (10 d)^2 / (pi d^3 / 6))
SEED = 2023
DEPOSITION_TIME = 1.0  # s: the last sphere has fallen the 0.15 m through water and the bed is at rest


def cloud(rng: np.random.Generator) -> np.ndarray:
    """x, y, z, r, fixed of the fixed layer and of the mobile spheres on a jittered lattice."""
    i, j = np.meshgrid(np.arange(SIDE), np.arange(SIDE), indexing="ij")
    fixed = np.column_stack([i.ravel() * D, j.ravel() * D, rng.random(SIDE * SIDE) * D])
    per_side = 8  # 8 x 8 sites a layer, spacing 1.25 d
    spacing = SIDE * D / per_side
    layers = math.ceil(MOBILE / per_side**2)
    a, b, c = np.meshgrid(np.arange(per_side), np.arange(per_side), np.arange(layers), indexing="ij")
    sites = np.column_stack([a.ravel(order="F"), b.ravel(order="F"), c.ravel(order="F")])[:MOBILE]
    mobile = (sites + 0.5) * spacing + np.array([0.0, 0.0, 1.5 * D]) + rng.uniform(-0.1, 0.1, (MOBILE, 3)) * D
    rows = np.vstack(
        [np.column_stack([fixed, np.ones(len(fixed))]), np.column_stack([mobile, np.zeros(MOBILE)])]
    )
    return np.insert(rows, 3, D / 2, axis=1)


def main(run_dir: Path) -> None:
    rows = cloud(np.random.default_rng(SEED))
    run_dir.mkdir(parents=True, exist_ok=True)
    header = "x,y,z,r,fixed"
    np.savetxt(run_dir / "cloud.csv", rows, delimiter=",", header=header, comments="", fmt="%.10g")
    case = (ROOT / "configs" / "bedload-yade.toml").read_text()
    case = case.replace('path = "bedload-yade-bed.csv"', 'path = "cloud.csv"')
    # still water: vertical gravity (the tilted one would drive the flow), the fluid at rest
    case = case.replace('initial = "steady"', 'initial = "rest"')
    case = case.replace("gravity = [0.490296, 0.0, -9.797740]", "gravity = [0.0, 0.0, -9.81]")
    assert 'path = "cloud.csv"' in case and 'initial = "rest"' in case and "-9.81]" in case
    (run_dir / "deposition.toml").write_text(case)
    api.run(run_dir / "deposition.toml", run_dir / "run", overwrite=True, until=DEPOSITION_TIME)
    with h5py.File(run_dir / "run" / "trajectory.h5", "r") as f:
        pos = f["particles/trajectory/position/value"][-1]
    rows[:, :3] = pos
    out = ROOT / "configs" / "bedload-yade-bed.csv"
    np.savetxt(out, rows, delimiter=",", header=header, comments="", fmt="%.10g")
    print(f"{out}: {len(rows)} spheres, the bed's top sphere at z = {pos[:, 2].max():.4f} m")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else ROOT / "runs" / "bedload-yade-deposition")
