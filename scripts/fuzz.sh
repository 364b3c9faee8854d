#!/usr/bin/env bash
# Runs every cargo-fuzz target in fuzz/ for a fixed number of runs with a fixed seed (short,
# for CI), or longer when asked. A new target in fuzz/Cargo.toml is picked up by itself
# (`cargo fuzz list`); inputs in fuzz/seeds/<target>/ seed its corpus. A run repeats exactly
# only from the same corpus: libFuzzer keeps what it finds in fuzz/corpus/<target>/ (ignored
# by git) and starts the next run from it, so a fresh checkout (CI) is reproducible, and a
# local run is once fuzz/corpus/ is deleted.
#
#   scripts/fuzz.sh                     every target, FUZZ_RUNS (20000) runs each
#   scripts/fuzz.sh cdr_decode          only the named targets
#   scripts/fuzz.sh --help              this text
#   FUZZ_RUNS=2000000 FUZZ_SEED=7 scripts/fuzz.sh cdr_decode    a longer session
#   FUZZ_SANITIZER=none scripts/fuzz.sh  without AddressSanitizer (faster; default: address)
#
# Needs cargo-fuzz (scripts/setup.sh installs it). Works with the stable compiler:
# RUSTC_BOOTSTRAP=1 lets it accept the -Z flags cargo-fuzz passes (sanitizer, coverage).
# A crash stops the script with the failing input under fuzz/artifacts/<target>/.
set -euo pipefail
for arg in "$@"; do
    case "$arg" in
        -h | --help) sed -n '2,/^[^#]/{/^#/p}' "$0"; exit 0 ;;
        -*) echo "fuzz: unknown option '$arg' (try --help)" >&2; exit 2 ;;
    esac
done
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
RUNS="${FUZZ_RUNS:-20000}"
SEED="${FUZZ_SEED:-1}"
SANITIZER="${FUZZ_SANITIZER:-address}"
# Fuzz builds use their own compiler flags: keep them apart from the workspace's build.
TARGET_DIR="${CARGO_TARGET_DIR:-$ROOT/target}/fuzz"

say() { printf '\033[1mfuzz:\033[0m %s\n' "$*"; }

if ! cargo fuzz --version >/dev/null 2>&1; then
    echo "fuzz: cargo-fuzz is not installed: run scripts/setup.sh (or 'cargo install cargo-fuzz --locked')" >&2
    exit 1
fi
export RUSTC_BOOTSTRAP=1

cd "$ROOT/fuzz"
mapfile -t known < <(cargo fuzz list)
[ "${#known[@]}" -gt 0 ] || { echo "fuzz: no targets in fuzz/Cargo.toml" >&2; exit 1; }
if [ "$#" -gt 0 ]; then
    targets=("$@")
    for target in "${targets[@]}"; do
        printf '%s\n' "${known[@]}" | grep -qxF -- "$target" \
            || { echo "fuzz: no target '$target' in fuzz/Cargo.toml (targets: ${known[*]})" >&2; exit 2; }
    done
else
    targets=("${known[@]}")
fi

# One cargo build for all targets: shared dependencies compile once, in parallel.
say "building ${targets[*]} (sanitizer: $SANITIZER)"
build_args=(--sanitizer "$SANITIZER" --target-dir "$TARGET_DIR")
if [ "$#" -gt 0 ]; then
    for target in "${targets[@]}"; do
        cargo fuzz build "${build_args[@]}" "$target" || { echo "fuzz: building $target failed" >&2; exit 1; }
    done
else
    cargo fuzz build "${build_args[@]}" || { echo "fuzz: building the fuzz targets failed" >&2; exit 1; }
fi

for target in "${targets[@]}"; do
    corpus="corpus/$target"
    mkdir -p "$corpus"
    seeds=()
    [ -d "seeds/$target" ] && seeds=("seeds/$target/")
    say "$target: $RUNS runs, seed $SEED"
    start=$SECONDS
    log="$TARGET_DIR/$target.log"
    mkdir -p "$TARGET_DIR"
    # -rss_limit_mb also limits single allocations: unbounded allocation is a finding.
    if ! cargo fuzz run --sanitizer "$SANITIZER" --target-dir "$TARGET_DIR" "$target" "$corpus" "${seeds[@]}" -- \
        -runs="$RUNS" -seed="$SEED" -max_len=65536 -rss_limit_mb=1024 -timeout=10 -print_final_stats=1 \
        >"$log" 2>&1; then
        tail -n 80 "$log" >&2
        echo "fuzz: $target FAILED (full log: $log; the input is under fuzz/artifacts/$target/)" >&2
        exit 1
    fi
    grep -E '^(Done|stat::number_of_executed_units|stat::peak_rss_mb|INFO: seed corpus)' "$log" || true
    say "$target: ok in $((SECONDS - start)) s"
done
