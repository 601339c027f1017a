"""Time sphere against YADE on configs/bedload-yade.toml (the scene of YADE's two-way coupled
bedload example), in alternating rounds, one core each: wall time per simulated second of the
coupled flow, from the same deposited bed (configs/bedload-yade-bed.csv). YADE runs our script
yade_bedload.py of that scene with Debian's `yade` (skipped, saying so, when it is absent).

    python benchmarks/peers/bedload_compare.py [simulated seconds per round] [rounds]
"""

import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np

from sphere_cli.bench.vans1d import measure

HERE = Path(__file__).resolve().parent
CASE = HERE.parents[1] / "configs" / "bedload-yade.toml"
BED = CASE.with_name("bedload-yade-bed.csv")
YADE_LINE = re.compile(r"YADE: ([0-9.]+) s per simulated second, (\d+) steps, dt (\S+) s")


def run_yade(seconds: float) -> float:
    command = ["yade", "-n", "-x", "-j1", str(HERE / "yade_bedload.py"), str(BED), repr(seconds)]
    out = subprocess.run(command, capture_output=True, text=True, cwd=HERE)
    found = YADE_LINE.search(out.stdout)
    if out.returncode != 0 or found is None:
        sys.exit(f"yade failed (exit {out.returncode}):\n{out.stdout[-3000:]}\n{out.stderr[-3000:]}")
    print(found.group(0))
    return float(found.group(1))


def main(seconds: float, rounds: int) -> None:
    yade = shutil.which("yade") is not None
    if not yade:
        print("YADE is not installed (yade not on PATH): sphere alone")
    ours, theirs = [], []
    for _ in range(rounds):
        row = measure(CASE, 1, seconds)
        ours.append(row["per_simulated_second"])
        print(
            f"sphere: {ours[-1]:.3f} s per simulated second, {row['steps']} steps, "
            f"{row['particle_steps_per_second'] / 1e6:.3f} M particle-steps/s"
        )
        if yade:
            theirs.append(run_yade(seconds))
    print(f"sphere: median {np.median(ours):.2f} s per simulated second ({rounds} rounds of {seconds} s)")
    if yade:
        ratio = np.array(theirs) / np.array(ours)
        print(f"YADE: median {np.median(theirs):.2f} s per simulated second")
        print(
            f"sphere faster than YADE per simulated second, round by round: median {np.median(ratio):.2f} "
            f"(min {ratio.min():.2f}, max {ratio.max():.2f})"
        )


if __name__ == "__main__":
    args = sys.argv[1:]
    main(float(args[0]) if args else 0.5, int(args[1]) if len(args) > 1 else 3)
