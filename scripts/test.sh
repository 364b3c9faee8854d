#!/usr/bin/env bash
# Runs every test of the project: formatting, lints, unit and cross-crate tests (including the
# external checkers in .venv and the multi-process DDS tests in private network namespaces),
# and short fuzzing runs. Run scripts/setup.sh once first.
#
#   scripts/test.sh           everything
#   scripts/test.sh --quick   cargo tests only (no fmt/clippy/fuzz)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"
QUICK=0
for arg in "$@"; do
    case "$arg" in
        --quick) QUICK=1 ;;
        -h | --help) sed -n '2,7p' "$0"; exit 0 ;;
        *) echo "test: unknown option '$arg' (try --help)" >&2; exit 2 ;;
    esac
done

say() { printf '\033[1mtest:\033[0m %s\n' "$*"; }

[ -x .venv/bin/python ] || { echo "test: .venv is missing: run scripts/setup.sh first" >&2; exit 1; }
[ -f .deps/onnxruntime/libonnxruntime.so ] || { echo "test: ONNX Runtime is missing: run scripts/setup.sh first" >&2; exit 1; }
export ORT_DYLIB_PATH="$ROOT/.deps/onnxruntime/libonnxruntime.so"
# Tests that need the external checkers fail (instead of skipping) when they are missing.
export LIDAR_HAR_REQUIRE_CHECKERS=1

if [ "$QUICK" = 0 ]; then
    say "cargo fmt --check"
    cargo fmt --all -- --check
    say "cargo clippy"
    cargo clippy --workspace --all-targets --locked -- -D warnings
    say "cargo check of the r2r (rcl) backend without ROS 2 (r2r doc-only)"
    cargo check -p lidar-har-ros --features r2r-doc-only --locked
fi

say "building binaries used by the cross-process tests"
cargo build --workspace --bins --locked
say "cargo test"
cargo test --workspace --locked

if [ "$QUICK" = 0 ] && [ -x scripts/fuzz.sh ]; then
    say "fuzzing (short, fixed number of runs)"
    scripts/fuzz.sh
fi
say "all tests passed"
