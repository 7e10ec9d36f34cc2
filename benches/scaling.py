#!/usr/bin/env python3
"""Strong scaling of the LAMMPS chute benchmark: Talus's rate at each size and thread count.

Runs `talus run` on `scenes/bench/chute.ron` replicated 1×1, 2×2 and 4×4 in x–y (32,000,
128,000 and 512,000 grains) with its number of steps set for each size, at each thread count, in
interleaved rounds (every size and thread count once per round, so that a slow stretch of
the machine touches all of them alike), and prints, for each size, the median rate, the
speed-up over 1 thread (median of each round's ratio), the parallel efficiency, the
per-grain rate against 32,000 grains at the same thread count, and the peak resident set
per grain. Every run's figures, with its stage times, go to a TSV file.

    python3 benches/scaling.py --threads 1,2,4,8,16 --rounds 3

The rate is `report.json`'s `grain_steps_per_second` (the build and the priming pass
excluded); the peak resident set is the kernel's (`wait4`), the whole process's.
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
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SCENE = ROOT / "scenes" / "bench" / "chute.ron"
DATA = ROOT / "scenes" / "bench" / "data.chute"
STAGES = [
    "integrate_positions",
    "broad_phase",
    "narrow_phase",
    "contact_forces",
    "apply_contact_forces",
    "integrate_velocities",
    "export",
]


def scene_text(replicate: int, steps: int) -> str:
    """`scenes/bench/chute.ron` replicated `replicate` × `replicate` times in x–y (its
    periodic extent widened to match, as the criterion benches do), with the data file's
    path made absolute and the number of steps set; fails loudly if the scene no longer
    has the fields it edits."""
    text = SCENE.read_text()
    edits = [
        (r"periodic:\s*\(x:\s*\(0\.0,\s*40\.0\),\s*y:\s*\(0\.0,\s*20\.0\)\)",
         f"periodic: (x: (0.0, {40.0 * replicate}), y: (0.0, {20.0 * replicate}))"),
        (r'LammpsData\(file:\s*"data\.chute",',
         f'LammpsData(file: "{DATA}", replicate: ({replicate}, {replicate}, 1),'),
        (r"\bsteps:\s*\d+", f"steps: {steps}"),
    ]
    for pattern, replacement in edits:
        text, n = re.subn(pattern, replacement, text, count=1)
        if n != 1:
            sys.exit(f"{SCENE}: found no `{pattern}` to edit")
    return text


def run_once(talus: str, scene: Path, threads: int, out: Path):
    """Runs one scene; returns (report, peak resident set in KiB)."""
    cmd = [talus, "run", str(scene), "--quiet", "--threads", str(threads), "--out", str(out)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    _, status, usage = os.wait4(proc.pid, 0)
    err = proc.stderr.read().decode(errors="replace")
    proc.stderr.close()
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({proc.returncode}):\n{err[-2000:]}")
    report = json.loads((out / "report.json").read_text())
    return report, usage.ru_maxrss


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--talus", default=str(ROOT / "target" / "release" / "talus"))
    ap.add_argument("--replicate", default="1,2,4", help="copies along x and y (1: 32,000 grains)")
    ap.add_argument("--steps", default="2000,400,150", help="steps for each replication")
    ap.add_argument("--threads", default="1,2")
    ap.add_argument("--rounds", type=int, default=3)
    ap.add_argument("--tsv", default="scaling.tsv", help="every run's figures")
    args = ap.parse_args()
    reps = [int(x) for x in args.replicate.split(",")]
    steps = [int(x) for x in args.steps.split(",")]
    threads = [int(x) for x in args.threads.split(",")]
    if len(steps) != len(reps):
        sys.exit("--steps needs one count per --replicate entry")

    work = Path(tempfile.mkdtemp(prefix="talus-scaling-"))
    scenes = {}
    for r, n in zip(reps, steps):
        scenes[r] = work / f"chute-r{r}.ron"
        scenes[r].write_text(scene_text(r, n))

    rate = {}  # (rep, threads) -> [rate per round]
    rss = {}
    grain_count = {}  # rep -> grains, as the runs report them
    with open(args.tsv, "w") as tsv:
        tsv.write("round\tgrains\tthreads\tsteps\tgrain_steps_per_second\tpeak_rss_kib\t"
                  + "\t".join(f"{s}_us_per_step" for s in STAGES) + "\n")
        for rnd in range(1, args.rounds + 1):
            for r in reps:
                for t in threads:
                    t0 = time.time()
                    report, peak = run_once(args.talus, scenes[r], t, work / "out")
                    wall = report["wall_clock"]
                    n_steps = report["steps"]
                    grains = report["grain_count"]
                    g = wall["grain_steps_per_second"]
                    rate.setdefault((r, t), []).append(g)
                    rss.setdefault((r, t), []).append(peak)
                    grain_count[r] = grains
                    stages = [wall["stages"].get(s, 0.0) * 1e6 / n_steps for s in STAGES]
                    tsv.write(f"{rnd}\t{grains}\t{t}\t{n_steps}\t{g:.0f}\t{peak}\t"
                              + "\t".join(f"{x:.1f}" for x in stages) + "\n")
                    tsv.flush()
                    print(f"round {rnd}: {grains:>7} grains, {t:>2} threads: "
                          f"{g / 1e6:7.2f} M grain-steps/s, peak {peak / 1024:6.0f} MiB "
                          f"({time.time() - t0:.1f} s)", flush=True)
    shutil.rmtree(work, ignore_errors=True)

    print("\nmedians over the rounds (speed-up: median of each round's ratio to 1 thread)")
    print("| grains | threads | M grain-steps/s | speed-up | efficiency | per grain vs 32,000 | bytes/grain |")
    print("|---:|---:|---:|---:|---:|---:|---:|")
    base_threads = threads[0]
    for r in reps:
        for t in threads:
            rates = rate[(r, t)]
            base = rate[(r, base_threads)]
            speedups = [a / b * base_threads for a, b in zip(rates, base)]
            small = rate.get((reps[0], t))
            per_grain = statistics.median(a / b for a, b in zip(rates, small)) if small else float("nan")
            grains = grain_count[r]
            bpg = statistics.median(rss[(r, t)]) * 1024 / grains
            s = statistics.median(speedups)
            print(f"| {grains:,} | {t} | {statistics.median(rates) / 1e6:.2f} | {s:.2f} | "
                  f"{s / t:.2f} | {per_grain:.2f} | {bpg:.0f} |")


if __name__ == "__main__":
    main()
