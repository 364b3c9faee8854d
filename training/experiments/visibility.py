"""Accuracy by how much of each window the person was seen in: windows bucketed by the number
of frames with any point in the image (the person hidden behind furniture or out of view in
the others), and the share of all errors that fall in windows not seen throughout.

    PYTHONPATH=training training/.venv/bin/python training/experiments/visibility.py \
        models/activity.onnx out/dataset5 [test|test_unseen]
"""

from common import last_step_probabilities, model_and_split_from_argv
from lidar_har_train.data import visible_steps


def main() -> None:
    model, split = model_and_split_from_argv()
    right = last_step_probabilities(model, split).argmax(-1) == split.labels[:, -1]
    frames = split.images.shape[1]
    seen = visible_steps(split.images).sum(axis=1)
    print(f"{split.name}: {len(right)} windows, accuracy {right.mean():.4f}")
    buckets = ((0, 0), (1, frames // 2), (frames // 2 + 1, frames * 3 // 4), (frames * 3 // 4 + 1, frames - 1),
               (frames, frames))
    for low, high in buckets:
        m = (seen >= low) & (seen <= high)
        accuracy = f"{right[m].mean():.4f}" if m.any() else "-"
        print(f"seen in {low}-{high} of {frames} frames: {m.mean() * 100:.1f} % of windows, accuracy {accuracy}")
    hidden = seen < frames
    print(f"errors in windows not seen throughout: {(~right & hidden).sum() / max(1, (~right).sum()):.4f} of all errors")


if __name__ == "__main__":
    main()
