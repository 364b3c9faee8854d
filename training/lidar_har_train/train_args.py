"""The training command's options (`python -m lidar_har_train.train`), apart from the
training: `training/train.sh --help` answers with them before training/.venv (PyTorch, a
~3.2 GB download) exists, from the system Python: it needs no third-party package.

    python3 -m lidar_har_train.train_args --help
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from .arguments import at_least, number


def parse_args(argv):
    p = argparse.ArgumentParser(prog="train", description="Trains the activity ConvLSTM on a `lidar-har dataset` "
                                "directory and exports the ONNX step model.")
    p.add_argument("--data", type=Path, required=True, help="dataset directory (index.json + .npy)")
    p.add_argument("--out", type=Path, required=True, help="ONNX file to write")
    p.add_argument("--hidden", type=at_least(1), default=16, help="ConvLSTM hidden channels")
    p.add_argument("--encoder-channels", type=at_least(1), default=8)
    p.add_argument("--batch", type=at_least(1), default=64)
    p.add_argument("--lr", type=number(above=0), default=3e-3, help="learning rate at the start")
    p.add_argument("--lr-final", type=number(minimum=0), default=1e-4,
                   help="learning rate at the end: a cosine from --lr reaches it when --max-epochs or "
                        "--time-budget-min runs out, whichever comes first (equal to --lr: constant)")
    p.add_argument("--max-epochs", type=at_least(1), default=40)
    p.add_argument("--patience", type=at_least(1), default=5, help="epochs without validation gain before stopping")
    p.add_argument("--steps-per-epoch", type=at_least(1), default=150, help="balanced batches drawn per epoch")
    p.add_argument("--time-budget-min", type=number(above=0), default=45.0,
                   help="stop training after this many minutes")
    p.add_argument("--val-fraction", type=number(above=0, below=1), default=0.15,
                   help="share of training episodes held for validation")
    p.add_argument("--threads", type=at_least(1), default=2)
    p.add_argument("--device", choices=["auto", "cpu", "cuda"], default="auto",
                   help="where to train: auto takes a CUDA GPU when PyTorch sees one (the export and its "
                        "parity check always run on the CPU)")
    p.add_argument("--seed", type=at_least(0), default=7)
    p.add_argument("--no-augment", action="store_true")
    p.add_argument("--shift-px", type=at_least(0), default=2,
                   help="augmentation: random shift of each window by up to this many pixels (less than half "
                        "the dataset's image size)")
    p.add_argument("--bf16", action="store_true",
                   help="bfloat16 autocast for the forward pass (GPUs, and CPUs with AVX-512 BF16 or AMX): 1.25x "
                        "the steps per second on the development machine; weights, loss and export stay float32")
    p.add_argument("--mask-hidden-steps", action="store_true",
                   help="leave out of the loss, and of the validation score, the steps at which the localiser did "
                        "not see the person (the dataset's positions; the robot publishes nothing for them)")
    p.add_argument("--init-from", type=Path, metavar="MODEL.onnx",
                   help="start from an exported model's weights instead of random ones (fine-tuning, or going on "
                        "where a time budget stopped); its image must be the dataset's, and its hidden and encoder "
                        "sizes replace --hidden and --encoder-channels")
    p.add_argument("--skip-test-eval", action="store_true",
                   help="skip PyTorch metrics on the test splits (`lidar-har evaluate` gives them through ONNX Runtime)")
    return p.parse_args(argv)


if __name__ == "__main__":
    parse_args(sys.argv[1:])
