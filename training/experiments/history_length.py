"""Accuracy by frames of history: every window stepped from a zero state, each step scored
against that scan's activity, over the scans with the person in view (those the robot
publishes). On a dataset with windows longer than the model's `T`, this shows how far past
`T` the model stays right, which sets the lane period of the streaming classifier
(`lane_period_windows` in config/classifier.yaml).

    PYTHONPATH=training training/.venv/bin/python training/experiments/history_length.py \\
        models/activity.onnx out/dataset7 [test|test_unseen]
"""
from common import model_and_split_from_argv, step_logits
from lidar_har_train.data import visible_steps


def main() -> None:
    model, split = model_and_split_from_argv()
    predicted = step_logits(model, split).argmax(-1)
    seen = visible_steps(split.images)
    for step in range(predicted.shape[1]):
        scored = seen[:, step]
        right = predicted[scored, step] == split.labels[scored, step]
        print(f"history {step + 1:3d} scans: accuracy {right.mean():.4f} ({scored.sum()} scans)")


if __name__ == "__main__":
    main()
