#!/usr/bin/env bash
# Trains the activity ConvLSTM on a `lidar-har dataset` directory and exports the ONNX step
# model (with a parity check against PyTorch). Creates training/.venv when missing
# (torch is a ~3.2 GB CUDA build from PyPI; it trains on the CPU).
#
#   training/train.sh --data out/dataset --out models/activity.onnx [--hidden 16 ...]
#   training/train.sh --setup    # only creates training/.venv when missing
#
# All options: training/train.sh --help (answered without training/.venv: the options need
# no PyTorch, and the system python3 reads them)
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
VENV="$HERE/.venv"
export PYTHONPATH="$HERE${PYTHONPATH:+:$PYTHONPATH}"
for arg in "$@"; do
    if [ "$arg" = "-h" ] || [ "$arg" = "--help" ]; then
        exec python3 -m lidar_har_train.train_args "$@"
    fi
done
if [ ! -x "$VENV/bin/python" ] || ! "$VENV/bin/python" -c 'import torch, onnx, onnxruntime' 2>/dev/null; then
    echo "train.sh: creating $VENV from training/requirements.txt (a few minutes)" >&2
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install -q -r "$HERE/requirements.txt"
fi
if [ "$*" = "--setup" ]; then
    exit 0
fi
exec "$VENV/bin/python" -m lidar_har_train.train "$@"
