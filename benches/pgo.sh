#!/usr/bin/env bash
# Builds a profile-guided (PGO) `talus` binary into target/pgo/talus, trained on LAMMPS's
# chute benchmark (`docs/performance.md`, "A profile-guided build").
#
#     benches/pgo.sh                  # needs: rustup component add llvm-tools
#     benches/pgo.sh SCENE.ron ...    # trained on these scenes instead, each on 1 and 2 threads
#
# Talus's own crates (the workspace's: crates/, plugins/ and the `talus` binary) are built
# twice more: first instrumented, then, after the training runs, with the profile those runs
# recorded. The dependencies keep their plain release build (a PGO build of them as well
# would cost two cold builds of bevy_ecs and rerun, and the step's hot code is Talus's own).
# The training runs are, by default, the 32,000-grain chute on 1 and 2 threads and its
# 512,000-grain replica on 1; a profile from the runs a user makes most is better for them.
# Results are bit for bit those of the plain build: a profile changes how the
# compiler lays out and inlines code, never what the code computes. The plain build is
# restored at the end (target/release/talus).
set -euo pipefail

root=$(cd "$(dirname "$0")/.." && pwd)
# The training scenes named on the command line, as absolute paths (the script works from
# the repository's root).
scenes=()
for scene in "$@"; do
    if [ ! -f "$scene" ]; then
        echo "pgo.sh: no scene file $scene" >&2
        exit 1
    fi
    scenes+=("$(cd "$(dirname "$scene")" && pwd)/$(basename "$scene")")
done
cd "$root"
host=$(rustc -vV | sed -n 's/^host: //p')
profdata="$(rustc --print sysroot)/lib/rustlib/$host/bin/llvm-profdata"
if [ ! -x "$profdata" ]; then
    echo "pgo.sh: no llvm-profdata in the toolchain; install it with: rustup component add llvm-tools" >&2
    exit 1
fi

work="$root/target/pgo/work"
rm -rf "$work"
mkdir -p "$work/raw" "$work/scenes"

# The wrapper adds $PGO_FLAGS to the workspace's crates only: cargo names their sources by
# paths relative to the workspace, and the dependencies' by absolute paths.
wrapper="$work/rustc-wrapper"
cat > "$wrapper" <<'WRAPPER'
#!/usr/bin/env bash
rustc="$1"
shift
for arg in "$@"; do
    case "$arg" in
        /*) ;;
        *.rs) exec "$rustc" "$@" $PGO_FLAGS ;;
    esac
done
exec "$rustc" "$@"
WRAPPER
chmod +x "$wrapper"

# Cargo does not see $PGO_FLAGS: the workspace's sources are touched so that it rebuilds them.
touch_workspace() { find crates plugins src -name '*.rs' -exec touch {} +; }
build_with() {
    touch_workspace
    PGO_FLAGS="$1" RUSTC_WRAPPER="$wrapper" cargo build --release --bin talus
}

echo "pgo.sh: 1/4 the instrumented build"
build_with "-Cprofile-generate=$work/raw"

echo "pgo.sh: 2/4 the training runs"
# The chute at 32,000 grains on 1 and 2 threads, and its 512,000-grain replica on 1.
train_on_chute() {
    cp scenes/bench/data.chute "$work/scenes/"
    python3 - "$work/scenes" <<'PY'
import sys
from pathlib import Path
sys.path.insert(0, "benches/lammps")
import race
folder = Path(sys.argv[1])
race.talus_scene(folder, 1, 600)
race.talus_scene(folder, 4, 60)
PY
    target/release/talus run "$work/scenes/chute-1x1-600.ron" --quiet --threads 1 --out "$work/out"
    target/release/talus run "$work/scenes/chute-1x1-600.ron" --quiet --threads 2 --out "$work/out"
    target/release/talus run "$work/scenes/chute-4x4-60.ron" --quiet --threads 1 --out "$work/out"
}
export LLVM_PROFILE_FILE="$work/raw/talus-%p-%m.profraw"
if [ "${#scenes[@]}" -eq 0 ]; then
    train_on_chute
else
    for scene in "${scenes[@]}"; do
        for threads in 1 2; do
            target/release/talus run "$scene" --quiet --threads "$threads" --out "$work/out"
        done
    done
fi
unset LLVM_PROFILE_FILE

echo "pgo.sh: 3/4 the profile-guided build"
"$profdata" merge -o "$work/talus.profdata" "$work"/raw/*.profraw
build_with "-Cprofile-use=$work/talus.profdata"
cp target/release/talus target/pgo/talus

echo "pgo.sh: 4/4 the plain build, restored"
touch_workspace
cargo build --release --bin talus

echo "pgo.sh: target/pgo/talus"
