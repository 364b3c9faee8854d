"""Two streaming lanes, offline: at each scan of the second half of a window the oldest lane
(this window, stepped from its start) against its average with the younger lane (the next
window, which starts T/2 scans later), over the scans with the person in view. On a dataset
with stride T/2 (the default), consecutive windows of one episode are exactly the two lanes
of the streaming classifier at a lane period of T, each with its own room-fixed framing.

    PYTHONPATH=training training/.venv/bin/python training/experiments/lane_average.py \\
        models/activity.onnx out/dataset5 [test|test_unseen]
"""
import sys
from pathlib import Path

import numpy as np
import torch

from common import model_and_split_from_argv, step_logits
from lidar_har_train.data import load_index, visible_steps


def main() -> None:
    model, split = model_and_split_from_argv()
    data = sys.argv[2]
    rows = sorted((w for w in load_index(Path(data))["windows"] if w["split"] == split.name),
                  key=lambda w: w["row"])
    probabilities = torch.softmax(torch.from_numpy(step_logits(model, split)), -1).numpy()
    seen = visible_steps(split.images)
    steps = probabilities.shape[1]
    half = steps // 2
    older = np.array([i for i in range(len(rows) - 1)
                      if rows[i + 1]["episode"] == rows[i]["episode"]
                      and rows[i + 1]["start_scan"] - rows[i]["start_scan"] == half])
    if len(older) == 0:
        sys.exit(f"{data}: no windows starting T/2 = {half} scans apart (make the dataset with --stride {half})")
    print(f"{len(older)} pairs of lanes")
    for weight in (0.0, 0.25, 0.5):
        right = scored = 0
        for step in range(half, steps):
            mixed = (1 - weight) * probabilities[older, step] + weight * probabilities[older + 1, step - half]
            keep = seen[older, step]
            right += (mixed.argmax(-1) == split.labels[older, step])[keep].sum()
            scored += keep.sum()
        print(f"younger lane weighted {weight:.2f}: accuracy {right / scored:.4f} ({scored} scans)")


if __name__ == "__main__":
    main()
