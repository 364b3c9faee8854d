"""What the experiments load: the model (rebuilt in PyTorch from its ONNX weights), one split
of a dataset, and the model's output over each window stepped from a zero state."""
import sys
from pathlib import Path

import numpy as np
import torch

from lidar_har_train.data import Split, load_index, load_split
from lidar_har_train.export import model_from_onnx


def model_and_split_from_argv():
    """`MODEL.onnx DATASET_DIR [SPLIT]` (split `test` by default)."""
    if len(sys.argv) < 3:
        sys.exit(f"usage: {sys.argv[0]} MODEL.onnx DATASET_DIR [test|test_unseen]")
    model_path, data = Path(sys.argv[1]), Path(sys.argv[2])
    split_name = sys.argv[3] if len(sys.argv) > 3 else "test"
    torch.set_num_threads(2)
    index = load_index(data)
    split = load_split(data, index, split_name)
    if split is None:
        sys.exit(f"{data}: no {split_name} split")
    return model_from_onnx(model_path, index["spec"]), split


def step_logits(model, split: Split, transform=lambda windows: windows) -> np.ndarray:
    """Logits at every scan of every window, `[N, T, 9]`; `transform` maps `[B, T, S, S]` windows."""
    out = []
    with torch.no_grad():
        for start in range(0, len(split), 512):
            windows = np.ascontiguousarray(transform(split.images[start : start + 512]))
            out.append(model(torch.from_numpy(windows.astype(np.float32) / 255.0)).numpy())
    return np.concatenate(out)


def last_step_probabilities(model, split: Split, transform=lambda windows: windows) -> np.ndarray:
    """Softmax at each window's last scan, `[N, 9]`."""
    logits = step_logits(model, split, transform)[:, -1]
    return torch.softmax(torch.from_numpy(logits), -1).numpy()
