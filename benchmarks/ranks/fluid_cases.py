"""Write the fluid cases of docs/performance.md's "Fluid cases on ranks": 16 000 glass beads on a
lattice (radius 0.5 mm, 40 x 40 mm across) under a fluid grid of 32 x 32 x 64 cells in a
40 x 40 x 80 mm box, from the example cases scaled up:

- `navier-stokes-16000.toml`: configs/fluidized-bed.toml (Navier-Stokes, Gidaspow's drag, the
  lowest 2 mm of beads fixed, the grid every 5 steps), the bottom pressure raised to hold the
  taller column (934.8 Pa);
- `darcy-16000.toml`: configs/seepage-pulses-darcy.toml (Darcy, the pulsed bottom pressure,
  the grid every step).

    python benchmarks/ranks/fluid_cases.py [folder]

then time each on one rank and on two, one thread a rank, alternating (this machine's speed
drifts by tens of per cent between minutes):

    export OMP_WAIT_POLICY=PASSIVE NUMBA_NUM_THREADS=1
    sphere run FOLDER/darcy-16000.toml --until 0.001 -o A
    mpiexec -n 2 sphere run FOLDER/darcy-16000.toml --until 0.001 -o B

(run.log and the last line give the wall time and the particle-steps per second)."""

import sys
from pathlib import Path

CONFIGS = Path(__file__).resolve().parents[2] / "configs"

# (the case it is made from, the lines replaced: old -> new)
CASES = {
    "navier-stokes-16000.toml": (
        "fluidized-bed.toml",
        [
            ("upper = [0.004, 0.004, 0.032]", "upper = [0.04, 0.04, 0.08]"),
            (
                "count = 192                         # 12 layers of 4 x 4: 4 fixed (the distributor), 8 free",
                "count = 16000                       # 10 layers of 40 x 40: 2 fixed, 8 free",
            ),
            ("region_upper = [0.004, 0.004, 0.012]", "region_upper = [0.04, 0.04, 0.012]"),
            ("region_upper = [0.004, 0.004, 0.004]", "region_upper = [0.04, 0.04, 0.002]"),
            ("cells = [1, 1, 8]", "cells = [32, 32, 64]"),
            ("pressure = 463.92", "pressure = 934.8"),
        ],
    ),
    "darcy-16000.toml": (
        "seepage-pulses-darcy.toml",
        [
            ("upper = [0.01, 0.01, 0.03]", "upper = [0.04, 0.04, 0.08]"),
            ("count = 1000\n", "count = 16000\n"),
            ("region_upper = [0.01, 0.01, 0.0105]", "region_upper = [0.04, 0.04, 0.0105]"),
            ("cells = [4, 4, 12]", "cells = [32, 32, 64]"),
        ],
    ),
}


def write(folder: Path) -> list[Path]:
    folder.mkdir(parents=True, exist_ok=True)
    written = []
    for name, (source, replacements) in CASES.items():
        text = (CONFIGS / source).read_text()
        for old, new in replacements:
            if text.count(old) != 1:
                raise SystemExit(f"configs/{source} no longer holds {old!r} once: update {__file__}")
            text = text.replace(old, new)
        (folder / name).write_text(text)
        written.append(folder / name)
    return written


if __name__ == "__main__":
    for path in write(Path(sys.argv[1] if len(sys.argv) > 1 else "bench-results/fluid-cases")):
        print(path)
