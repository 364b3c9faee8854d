"""Test-time augmentation, measured: the committed model's accuracy when its softmax is averaged
over 1, 2, 4 or 8 of the square symmetries it was trained with (each symmetry needs its own
ConvLSTM state, so n symmetries cost n times the steps per scan on the robot).

    PYTHONPATH=training training/.venv/bin/python training/experiments/symmetry_average.py \
        models/activity.onnx out/dataset5 [test|test_unseen]
"""
import time

import numpy as np

from common import last_step_probabilities, model_and_split_from_argv
from lidar_har_train.data import CLASSES

SYMMETRIES = [(0, False), (0, True), (2, False), (2, True), (1, False), (1, True), (3, False), (3, True)]


def symmetry(quarter_turns: int, flip: bool):
    def apply(windows: np.ndarray) -> np.ndarray:
        turned = np.rot90(windows, quarter_turns, axes=(2, 3))
        return turned[:, :, :, ::-1] if flip else turned

    return apply


def main() -> None:
    model, split = model_and_split_from_argv()
    labels = split.labels[:, -1]
    within = (split.labels == split.labels[:, -1:]).all(axis=1)
    fall = labels == CLASSES.index("falling_down")
    probs = []
    for quarter_turns, flip in SYMMETRIES:
        started = time.time()
        probs.append(last_step_probabilities(model, split, symmetry(quarter_turns, flip)))
        print(f"rotation {quarter_turns * 90} flip {flip}: {np.mean(probs[-1].argmax(-1) == labels):.4f} "
              f"({time.time() - started:.0f} s)", flush=True)
    for n in (1, 2, 4, 8):
        p = np.mean(probs[:n], axis=0).argmax(-1)
        print(f"{n} symmetries: all {np.mean(p == labels):.4f}, within one activity "
              f"{np.mean(p[within] == labels[within]):.4f}, falling_down recall {np.mean(p[fall] == labels[fall]):.4f}")


if __name__ == "__main__":
    main()
