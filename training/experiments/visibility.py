"""Accuracy by how much of each window the person was seen in: windows bucketed by the number
of frames with any point in the image (the person hidden behind furniture or out of view in
the others), and the share of all errors that fall in windows not seen throughout.

    PYTHONPATH=training training/.venv/bin/python training/experiments/visibility.py \
        models/activity.onnx out/dataset5 [test|test_unseen]
"""
import sys
from pathlib import Path

import numpy as np
import torch

from lidar_har_train.data import load_index, load_split
from lidar_har_train.export import model_from_onnx


def main() -> None:
    model_path, data = Path(sys.argv[1]), Path(sys.argv[2])
    split_name = sys.argv[3] if len(sys.argv) > 3 else "test"
    torch.set_num_threads(2)
    model = model_from_onnx(model_path)
    split = load_split(data, load_index(data), split_name)
    labels = split.labels[:, -1]
    predicted = []
    with torch.no_grad():
        for start in range(0, len(split), 512):
            x = torch.from_numpy(split.images[start : start + 512].astype(np.float32) / 255.0)
            predicted.append(model(x)[:, -1].argmax(-1).numpy())
    right = np.concatenate(predicted) == labels
    frames = split.images.shape[1]
    seen = (split.images > 0).any(axis=(2, 3)).sum(axis=1)
    print(f"{split_name}: {len(right)} windows, accuracy {right.mean():.4f}")
    for low, high in ((0, 0), (1, frames // 2), (frames // 2 + 1, frames * 3 // 4), (frames * 3 // 4 + 1, frames - 1),
                      (frames, frames)):
        m = (seen >= low) & (seen <= high)
        accuracy = f"{right[m].mean():.4f}" if m.any() else "-"
        print(f"seen in {low}-{high} of {frames} frames: {m.mean() * 100:.1f} % of windows, accuracy {accuracy}")
    hidden = seen < frames
    print(f"errors in windows not seen throughout: {(~right & hidden).sum() / max(1, (~right).sum()):.4f} of all errors")


if __name__ == "__main__":
    main()
