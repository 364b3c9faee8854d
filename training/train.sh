#!/usr/bin/env bash
# Trains the activity ConvLSTM on a `lidar-har dataset` directory and exports the ONNX step
# model (with a parity check against PyTorch). Creates training/.venv when missing
# (torch is a ~3.2 GB CUDA build from PyPI; it trains on the CPU).
#
#   training/train.sh --data out/dataset --out models/activity.onnx [--hidden 16 ...]
#
# All options: training/train.sh --help
set -euo pipefail
HERE="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
VENV="$HERE/.venv"
if [ ! -x "$VENV/bin/python" ] || ! "$VENV/bin/python" -c 'import torch, onnx, onnxruntime' 2>/dev/null; then
    echo "train.sh: creating $VENV from training/requirements.txt (a few minutes)" >&2
    python3 -m venv "$VENV"
    "$VENV/bin/pip" install -q -r "$HERE/requirements.txt"
fi
export PYTHONPATH="$HERE${PYTHONPATH:+:$PYTHONPATH}"
exec "$VENV/bin/python" -m lidar_har_train.train "$@"
