"""A small dataset in the layout `lidar-har dataset` writes (docs/training.md), for tests."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from lidar_har_train.data import CLASSES

WINDOW, SIZE = 8, 16


def write_dataset(out: Path, episodes: dict | None = None, windows_per_episode: int = 4) -> Path:
    """Windows of a bar whose place says the class, with localiser positions; `episodes`:
    how many per split."""
    episodes = episodes or {"train": 6, "test": 2, "test_unseen": 1}
    out.mkdir(parents=True, exist_ok=True)
    rng = np.random.default_rng(0)
    splits, listed, windows = {}, [], []
    for split, count in episodes.items():
        images, labels, positions = [], [], []
        for _ in range(count):
            episode = len(listed)
            listed.append({"id": episode, "scene": "room", "scene_file": "room.yaml", "seed": episode,
                           "split": split, "scans": 40, "person_visible_scans": 40,
                           "windows": windows_per_episode})
            for w in range(windows_per_episode):
                label = int(rng.integers(len(CLASSES)))
                image = np.zeros((WINDOW, SIZE, SIZE), np.uint8)
                image[:, 2 + label : 4 + label, 5:9] = 255
                images.append(image)
                labels.append(np.full(WINDOW, label, np.uint8))
                positions.append(rng.normal(size=(WINDOW, 4)).astype(np.float32) * 0.1)
                windows.append({"split": split, "row": len(images) - 1, "episode": episode, "start_scan": 4 * w,
                                "start_s": 0.2 * w, "label": CLASSES[label]})
        for kind, arrays in (("images", images), ("labels", labels), ("positions", positions)):
            np.save(out / f"{split}_{kind}.npy", np.stack(arrays))
        splits[split] = {"windows": len(images), "images": f"{split}_images.npy", "labels": f"{split}_labels.npy",
                         "positions": f"{split}_positions.npy", "class_counts": [0] * len(CLASSES)}
    index = {
        "format_version": 1,
        "spec": {"representation": "boolean_grid", "framing": "room_fixed", "size": SIZE, "resolution_m": 0.08,
                 "window": WINDOW, "stride": 4, "scan_rate_hz": 20.0, "fixed_lidar": False},
        "classes": CLASSES,
        "generator": {"command": "tests", "scenes": ["room"], "held_out": [], "episodes": len(listed), "seed": 1,
                      "episode_seconds": 2, "person_points": "synthetic"},
        "splits": splits, "episodes": listed, "windows": windows,
    }
    (out / "index.json").write_text(json.dumps(index))
    return out
