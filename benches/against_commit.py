#!/usr/bin/env python3
"""Races the current Talus against the code of an earlier commit on the chute, in interleaved rounds.

Speed figures taken on other days do not compare: this project's machines drift by 15 % and
more between stretches, and a session may land on a faster or slower host. This script
measures the code's own progress side by side instead. It builds `COMMIT` in a temporary git
worktree and runs that build and the current one (`--talus`, by default this checkout's
`target/release/talus`) in turn, round by round. Each runs its own tree's
`scenes/bench/chute.ron`, replicated and lengthened to each size as `lammps/race.py` does.
It prints each run's grain-steps per second, and per size the medians, the median of the
rounds' ratios (current / old) with its quartiles, and each side's per-grain rate against
the first size.

The old tree gets this checkout's `.cargo/config.toml` and `[profile.*]` tables, so that both
builds use the same target CPU and optimisation: the ratio is the code's alone. It builds in
a target directory of its own, `target/against-commit` by default. The first use builds the
dependencies there (10-25 minutes on two cores), and later uses reuse them. It never builds
in this checkout's own `target/`: cargo names a workspace's units by their paths inside the
workspace, so a worktree's build there took over the checkout's fingerprints and its
`target/release/talus`, and a later `cargo build` reported the checkout fresh and left the
old binary in place (seen in session 59).

    cargo build --release --bin talus
    python3 benches/against_commit.py a69bcff --rounds 10

Each side's kinetic energies at the last step of its first run are printed too. A commit
from before a physics change gives other digits, which the page quoting the ratio should say.
"""

import argparse
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent / "lammps"))
from race import ROOT, talus_report, talus_scene  # noqa: E402  (shared with the LAMMPS race)

# (replication in x and y, steps): the 32,000-grain chute over 1,000 steps, and the
# 512,000-grain replica over 100.
DEFAULT_SIZES = "1x1000,4x100"


def parse_sizes(text: str) -> list[tuple[int, int]]:
    """`"1x1000,4x100"` as [(1, 1000), (4, 100)]."""
    sizes = []
    for item in text.split(","):
        m = re.fullmatch(r"\s*(\d+)x(\d+)\s*", item)
        if not m or int(m.group(1)) < 1 or int(m.group(2)) < 1:
            sys.exit(f"against_commit.py: --sizes wants COPIESxSTEPS,... (e.g. {DEFAULT_SIZES}), "
                     f"not `{item}`")
        sizes.append((int(m.group(1)), int(m.group(2))))
    return sizes


def profile_tables(cargo_toml: str) -> tuple[str, str]:
    """`cargo_toml` without its `[profile...]` tables, and those tables' text."""
    kept, profiles, in_profile = [], [], False
    for line in cargo_toml.splitlines(keepends=True):
        if re.match(r"\[", line):
            in_profile = line.startswith("[profile")
        (profiles if in_profile else kept).append(line)
    return "".join(kept), "".join(profiles)


def build_commit(commit: str, tree: Path, target_dir: Path) -> Path:
    """Builds `commit`'s `talus` in a worktree at `tree` with this checkout's build settings;
    returns the binary's path in `target_dir`."""
    subprocess.run(["git", "-C", str(ROOT), "worktree", "add", "--detach", str(tree), commit],
                   check=True, stdout=subprocess.DEVNULL)
    config = ROOT / ".cargo/config.toml"
    if config.exists():
        (tree / ".cargo").mkdir(exist_ok=True)
        shutil.copy(config, tree / ".cargo/config.toml")
    old_manifest, _ = profile_tables((tree / "Cargo.toml").read_text())
    _, profiles = profile_tables((ROOT / "Cargo.toml").read_text())
    (tree / "Cargo.toml").write_text(old_manifest.rstrip("\n") + "\n\n" + profiles)
    subprocess.run(["cargo", "build", "--release", "--bin", "talus"], cwd=tree, check=True,
                   env={**os.environ, "CARGO_TARGET_DIR": str(target_dir)})
    return target_dir / "release/talus"


def energies(report: dict) -> str:
    """The kinetic energies of a report's last sample."""
    samples = report.get("samples") or [{}]
    last = samples[-1]
    return (f"step {last.get('step')}: translational {last.get('translational_kinetic')}, "
            f"rotational {last.get('rotational_kinetic')}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("commit", help="the earlier commit to race (any git revision)")
    parser.add_argument("--talus", default=str(ROOT / "target/release/talus"),
                        help="the current binary (build it first)")
    parser.add_argument("--rounds", type=int, default=6)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--sizes", default=DEFAULT_SIZES,
                        help="COPIESxSTEPS,...: replicas of the chute in x and y, and steps")
    parser.add_argument("--target-dir", default=str(ROOT / "target/against-commit"),
                        help="where the old commit is built (kept for later runs; not this "
                             "checkout's own target directory)")
    args = parser.parse_args()
    sizes = parse_sizes(args.sizes)
    target_dir = Path(args.target_dir).resolve()
    if target_dir == (ROOT / "target").resolve():
        sys.exit("against_commit.py: --target-dir must not be this checkout's own target "
                 "directory (see the script's doc)")
    current_path = Path(args.talus)
    if not current_path.is_file():
        sys.exit(f"against_commit.py: no current binary at `{current_path}`: "
                 "run `cargo build --release --bin talus` first")
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        # The current binary, copied aside: it may be rebuilt while the rounds run.
        current = folder / "talus-current"
        shutil.copy2(current_path, current)
        tree = folder / "tree"
        try:
            built = build_commit(args.commit, tree, target_dir)
            old = folder / "talus-old"
            shutil.copy2(built, old)
            old_scene = tree / "scenes/bench/chute.ron"
            if not old_scene.exists():
                sys.exit(f"against_commit.py: {args.commit} has no scenes/bench/chute.ron")
            shutil.copy(ROOT / "scenes/bench/data.chute", folder)
            scenes = {
                size: (talus_scene(folder, *size, source=old_scene, tag="-old"),
                       talus_scene(folder, *size, tag="-current"))
                for size in sizes
            }
        finally:
            subprocess.run(["git", "-C", str(ROOT), "worktree", "remove", "--force", str(tree)],
                           check=False)
        rates = {size: ([], []) for size in sizes}
        for round_ in range(1, args.rounds + 1):
            for size in sizes:
                # Which side runs first alternates, so that neither always follows the other.
                sides = [(0, old, scenes[size][0]), (1, current, scenes[size][1])]
                if round_ % 2 == 0:
                    sides.reverse()
                for side, binary, scene in sides:
                    report = talus_report(binary, scene, folder / "out", args.threads)
                    rates[size][side].append(report["wall_clock"]["grain_steps_per_second"])
                    if round_ == 1:
                        print(f"{'old' if side == 0 else 'current'}, "
                              f"{32_000 * size[0] ** 2:,} grains: {energies(report)}")
                old_rate, current_rate = rates[size][0][-1], rates[size][1][-1]
                print(f"round {round_}: {32_000 * size[0] ** 2:>7} grains, {size[1]:>4} steps: "
                      f"{args.commit} {old_rate / 1e6:6.2f} M, current {current_rate / 1e6:6.2f} M, "
                      f"ratio {current_rate / old_rate:5.2f}", flush=True)
    print(f"\n{args.threads} thread(s), {args.rounds} rounds, against {args.commit}")
    print("\n| grains | steps | old (M grain-steps/s) | current | current / old, median of rounds "
          "(quartiles) | per-grain rate against the first size, old / current |")
    print("|---:|---:|---:|---:|---:|---:|")
    first = sizes[0]
    for size, (old_rates, current_rates) in rates.items():
        ratios = [c / o for c, o in zip(current_rates, old_rates)]
        quartiles = (statistics.quantiles(ratios, n=4) if len(ratios) > 1
                     else [ratios[0]] * 3)
        per_grain = [statistics.median(r / f for r, f in zip(rates[size][k], rates[first][k]))
                     for k in (0, 1)]
        print(f"| {32_000 * size[0] ** 2:,} | {size[1]} | {statistics.median(old_rates) / 1e6:.2f} "
              f"| {statistics.median(current_rates) / 1e6:.2f} | {statistics.median(ratios):.3f} "
              f"({quartiles[0]:.3f}–{quartiles[2]:.3f}) | {per_grain[0]:.2f} / {per_grain[1]:.2f} |")


if __name__ == "__main__":
    try:
        main()
    except subprocess.CalledProcessError as failed:
        sys.exit(f"against_commit.py: `{' '.join(map(str, failed.cmd))}` failed "
                 f"(exit status {failed.returncode})")
