"""Could the activity model place the pelvis better than the localiser does? (issue 4's "pose
head"). The activity model's ConvLSTM state after each scan is kept frozen; a small head is
fitted on it to predict the pelvis's offset from the localiser's position, on the training
split, and scored on the test splits (drawn rooms, and the held-out room) against the
localiser alone. Needs a dataset with `*_positions.npy` (`lidar-har dataset`, since session
22).

    PYTHONPATH=training training/.venv/bin/python \
        training/experiments/pose_offset.py models/activity.onnx out/pose81 [--train-windows N]

Scores: error of the pelvis over the scans the localiser saw (median / p95, metres), overall
and per activity, before and after the head.
"""

import argparse
import json
import time
from pathlib import Path

import numpy as np
import torch
from torch import nn

from lidar_har_train.data import CLASSES, load_index, load_split
from lidar_har_train.export import model_from_onnx

# Scans of each window whose state and offset are used: late enough for some history.
STEPS = (9, 14, 19)


def features(model, split, positions, rows):
    """The ConvLSTM state `[n, hidden, s, s]` (float16) at `STEPS` of the windows `rows`, the
    localiser's position from the image centre `[n, 2]`, the pelvis's offset from it `[n, 2]`
    and the activity `[n]`, for the scans the localiser saw."""
    states, located, offsets, labels = [], [], [], []
    with torch.no_grad():
        for start in range(0, len(rows), 512):
            batch = rows[start : start + 512]
            frames = torch.from_numpy(split.images[batch].astype(np.float32) / 255.0)
            h, c = model.zero_state(len(batch))
            for t in range(frames.shape[1]):
                _, h, c = model.step(frames[:, t : t + 1], h, c)
                if t not in STEPS:
                    continue
                pos = positions[batch, t]
                keep = np.isfinite(pos).all(axis=1)
                states.append(h[torch.from_numpy(keep)].numpy().astype(np.float16))
                located.append(pos[keep, 2:])
                offsets.append(pos[keep, :2] - pos[keep, 2:])
                labels.append(split.labels[batch, t][keep])
    return (np.concatenate(states), np.concatenate(located).astype(np.float32),
            np.concatenate(offsets).astype(np.float32), np.concatenate(labels))


class PoseHead(nn.Module):
    """State and localiser position in, pelvis offset from the localiser out."""

    def __init__(self, hidden: int, side: int):
        super().__init__()
        self.conv = nn.Sequential(nn.Conv2d(hidden, 32, 3, padding=1), nn.ReLU())
        self.mlp = nn.Sequential(nn.Linear(32 * side * side + 2, 64), nn.ReLU(), nn.Linear(64, 2))

    def forward(self, state, located):
        return self.mlp(torch.cat([self.conv(state).flatten(1), located], dim=1))


def fit(head, data, minutes: float, seed: int):
    states, located, offsets, _ = data
    rng = np.random.default_rng(seed)
    optimiser = torch.optim.Adam(head.parameters(), lr=1e-3)
    start, epoch = time.time(), 0
    while time.time() - start < minutes * 60:
        order = rng.permutation(len(states))
        total = 0.0
        for b in range(0, len(order), 256):
            idx = order[b : b + 256]
            pred = head(torch.from_numpy(states[idx].astype(np.float32)), torch.from_numpy(located[idx]))
            loss = nn.functional.smooth_l1_loss(pred, torch.from_numpy(offsets[idx]), beta=0.05)
            optimiser.zero_grad()
            loss.backward()
            optimiser.step()
            total += loss.item() * len(idx)
        epoch += 1
        print(f"epoch {epoch}: loss {total / len(order):.4f} ({(time.time() - start) / 60:.1f} min)", flush=True)


def predict(head, data):
    states, located, _, _ = data
    out = []
    with torch.no_grad():
        for b in range(0, len(states), 2048):
            out.append(head(torch.from_numpy(states[b : b + 2048].astype(np.float32)),
                            torch.from_numpy(located[b : b + 2048])).numpy())
    return np.concatenate(out)


def scores(errors, labels):
    def pair(e):
        return [round(float(np.median(e)), 3), round(float(np.percentile(e, 95)), 3)] if len(e) else None
    return {"scans": int(len(errors)), "median_p95_m": pair(errors),
            "per_activity": {CLASSES[k]: pair(errors[labels == k]) for k in range(len(CLASSES))}}


def main() -> None:
    parser = argparse.ArgumentParser()
    parser.add_argument("model", type=Path)
    parser.add_argument("data", type=Path)
    parser.add_argument("--train-windows", type=int, default=40000)
    parser.add_argument("--minutes", type=float, default=10.0)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args()
    torch.set_num_threads(2)
    torch.manual_seed(args.seed)
    index = load_index(args.data)
    model = model_from_onnx(args.model, index["spec"])
    model.eval()
    data = {}
    for name in ("train", "test", "test_unseen"):
        split = load_split(args.data, index, name)
        info = index["splits"][name]
        if "positions" not in info:
            raise SystemExit(f"{args.data}: no positions in split {name}; remake it with today's `lidar-har dataset`")
        positions = np.load(args.data / info["positions"])
        rows = np.arange(len(split))
        if name == "train" and len(rows) > args.train_windows:
            rows = np.sort(np.random.default_rng(args.seed).choice(rows, args.train_windows, replace=False))
        data[name] = features(model, split, positions, rows)
        print(f"{name}: {len(data[name][0])} seen scans from {len(rows)} windows", flush=True)
    head = PoseHead(model.hidden, model.state_size)
    fit(head, data["train"], args.minutes, args.seed)
    report = {}
    for name in ("train", "test", "test_unseen"):
        _, _, offsets, labels = data[name]
        before = np.linalg.norm(offsets, axis=1)
        after = np.linalg.norm(offsets - predict(head, data[name]), axis=1)
        report[name] = {"localiser": scores(before, labels), "with_head": scores(after, labels)}
        print(f"{name}: localiser {report[name]['localiser']['median_p95_m']} -> "
              f"with head {report[name]['with_head']['median_p95_m']} (median, p95 m)")
        for k in range(len(CLASSES)):
            b, a = report[name]["localiser"]["per_activity"][CLASSES[k]], report[name]["with_head"]["per_activity"][CLASSES[k]]
            print(f"    {CLASSES[k]:20s} {b} -> {a}")
    if args.json:
        args.json.write_text(json.dumps(report, indent=1) + "\n")


if __name__ == "__main__":
    main()
