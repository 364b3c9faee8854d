#!/usr/bin/env bash
# Accuracy against run time (docs/training.md): one dataset, training and evaluation per
# configuration of training/sweep.toml. About 90 minutes on 2 quiet CPU cores.
#
#   training/sweep.sh [--only NAME ...] [--report-only] [--retime]
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
ROOT="$(cd "$HERE/.." && pwd)"
cd "$ROOT"
"$HERE/train.sh" --setup # creates training/.venv when missing
case " $* " in
*" --report-only "* | *" --retime "*) ;;
*)
    cargo build --release --locked --bin lidar-har
    # The sweep's own copy: rebuilding while it runs must not change the binary half-way.
    mkdir -p out/sweep
    cp target/release/lidar-har out/sweep/lidar-har
    ;;
esac
export ORT_DYLIB_PATH="${ORT_DYLIB_PATH:-$ROOT/.deps/onnxruntime/libonnxruntime.so}"
export PYTHONPATH="$HERE${PYTHONPATH:+:$PYTHONPATH}"
exec "$HERE/.venv/bin/python" -m lidar_har_train.sweep --config "$HERE/sweep.toml" --out out/sweep \
    --lidar-har out/sweep/lidar-har "$@"
