"""Two run-time changes to the committed model's output, measured without retraining:

- class-frequency correction: training draws every class equally often, the test split has
  them at their natural frequencies (those of the dataset's training windows); `log p + tau log prior`
  for several `tau`;
- holding the last image with the person in view over the scans where they are hidden,
  instead of the empty image the model was trained with.

    PYTHONPATH=training training/.venv/bin/python training/experiments/run_time_variants.py \\
        models/activity.onnx out/dataset5 [test|test_unseen]
"""
import sys
from pathlib import Path

import numpy as np

from common import last_step_probabilities, model_and_split_from_argv
from lidar_har_train.data import CLASSES, visible_steps

FALL = CLASSES.index("falling_down")


def hold_last_seen(windows: np.ndarray) -> np.ndarray:
    held = windows.copy()
    seen = visible_steps(held)
    for t in range(1, held.shape[1]):
        fill = ~seen[:, t] & seen[:, t - 1]
        held[fill, t] = held[fill, t - 1]
        seen[fill, t] = True
    return held


def describe(name: str, predicted: np.ndarray, labels: np.ndarray) -> None:
    fall = labels == FALL
    print(f"{name}: accuracy {(predicted == labels).mean():.4f}, "
          f"falling recall {(predicted[fall] == FALL).mean():.4f}")


def main() -> None:
    model, split = model_and_split_from_argv()
    labels = split.labels[:, -1]
    probabilities = last_step_probabilities(model, split)
    train_last = np.load(Path(sys.argv[2]) / "train_labels.npy", mmap_mode="r")[:, -1]
    prior = np.bincount(train_last, minlength=len(CLASSES)) / len(train_last)
    for tau in (0.0, 0.25, 0.5, 1.0):
        corrected = np.log(probabilities + 1e-12) + tau * np.log(prior)
        describe(f"class-frequency correction, tau {tau}", corrected.argmax(-1), labels)
    held = last_step_probabilities(model, split, hold_last_seen)
    describe("last image in view held over hidden scans", held.argmax(-1), labels)


if __name__ == "__main__":
    main()
