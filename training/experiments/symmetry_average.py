"""Test-time augmentation, measured: the committed model's accuracy when its softmax is averaged
over 1, 2, 4 or 8 of the square symmetries it was trained with (each symmetry needs its own
ConvLSTM state, so n symmetries cost n times the steps per scan on the robot).

    PYTHONPATH=training training/.venv/bin/python training/experiments/symmetry_average.py \
        models/activity.onnx out/dataset5 [test|test_unseen]
"""
import sys
import time
from pathlib import Path

import numpy as np
import torch

from lidar_har_train.data import CLASSES, load_index, load_split
from lidar_har_train.export import model_from_onnx

SYMMETRIES = [(0, False), (0, True), (2, False), (2, True), (1, False), (1, True), (3, False), (3, True)]


def last_step_probabilities(model, images: np.ndarray, quarter_turns: int, flip: bool) -> np.ndarray:
    out = []
    with torch.no_grad():
        for start in range(0, len(images), 512):
            w = np.rot90(images[start : start + 512], quarter_turns, axes=(2, 3))
            if flip:
                w = w[:, :, :, ::-1]
            x = torch.from_numpy(np.ascontiguousarray(w).astype(np.float32) / 255.0)
            out.append(torch.softmax(model(x)[:, -1], -1).numpy())
    return np.concatenate(out)


def main() -> None:
    model_path, data = Path(sys.argv[1]), Path(sys.argv[2])
    split_name = sys.argv[3] if len(sys.argv) > 3 else "test"
    torch.set_num_threads(2)
    model = model_from_onnx(model_path)
    split = load_split(data, load_index(data), split_name)
    labels = split.labels[:, -1]
    within = (split.labels == split.labels[:, -1:]).all(axis=1)
    fall = labels == CLASSES.index("falling_down")
    probs = []
    for quarter_turns, flip in SYMMETRIES:
        started = time.time()
        probs.append(last_step_probabilities(model, split.images, quarter_turns, flip))
        print(f"rotation {quarter_turns * 90} flip {flip}: {np.mean(probs[-1].argmax(-1) == labels):.4f} "
              f"({time.time() - started:.0f} s)", flush=True)
    for n in (1, 2, 4, 8):
        p = np.mean(probs[:n], axis=0).argmax(-1)
        print(f"{n} symmetries: all {np.mean(p == labels):.4f}, within one activity "
              f"{np.mean(p[within] == labels[within]):.4f}, falling_down recall {np.mean(p[fall] == labels[fall]):.4f}")


if __name__ == "__main__":
    main()
