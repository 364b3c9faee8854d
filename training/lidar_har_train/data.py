"""Reads a dataset written by `lidar-har dataset` (layout in docs/training.md)."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

CLASSES = [
    "crawling",
    "falling_down",
    "getting_up",
    "lying_down",
    "running",
    "sitting_on_floor",
    "standing",
    "walking",
    "walking_unsteadily",
]


@dataclass
class Split:
    """The windows of one split: images `[N, T, S, S]` (uint8, value/255), labels `[N, T]`, and
    `seen` `[N, T]`: whether the localiser saw the person at each scan, as the robot publishes
    (a person seen outside a room-fixed image counts)."""

    name: str
    images: np.ndarray
    labels: np.ndarray
    episodes: np.ndarray
    seen: np.ndarray

    def __len__(self) -> int:
        return self.images.shape[0]

    def subset(self, mask: np.ndarray, name: str) -> "Split":
        return Split(name, self.images[mask], self.labels[mask], self.episodes[mask], self.seen[mask])


class DatasetError(Exception):
    pass


def load_index(data_dir: Path) -> dict:
    path = data_dir / "index.json"
    try:
        index = json.loads(path.read_text())
    except FileNotFoundError as err:
        raise DatasetError(f"{path}: no index.json; make the dataset with `lidar-har dataset`") from err
    except json.JSONDecodeError as err:
        raise DatasetError(f"{path}: not valid JSON ({err})") from err
    if index.get("classes") != CLASSES:
        raise DatasetError(f"{path}: classes {index.get('classes')} differ from the class order {CLASSES}")
    return index


def load_array(path: Path, mapped: bool = False) -> np.ndarray:
    """One `.npy` array (`mapped`: left on disk); a missing, unreadable or cut-short file is a
    DatasetError naming it, not a traceback."""
    try:
        return np.load(path, mmap_mode="r" if mapped else None)
    except OSError as err:
        raise DatasetError(f"{path}: cannot read the array: {err.strerror or err}") from err
    except (ValueError, EOFError) as err:
        raise DatasetError(f"{path}: not a whole .npy array ({err})") from err


def load_split(data_dir: Path, index: dict, name: str, mapped: bool = False) -> Split | None:
    """One split's windows; `mapped` leaves the images on disk (memory-mapped), for readers that
    go through them once in order."""
    info = index.get("splits", {}).get(name)
    if info is None or info.get("windows", 0) == 0:
        return None
    images = load_array(data_dir / info["images"], mapped)
    labels = load_array(data_dir / info["labels"])
    spec = index["spec"]
    expected = (info["windows"], spec["window"], spec["size"], spec["size"])
    if images.shape != expected or images.dtype != np.uint8:
        raise DatasetError(f"{data_dir / info['images']}: shape {images.shape} {images.dtype}, expected {expected} uint8")
    if labels.shape != expected[:2] or labels.max(initial=0) >= len(CLASSES):
        raise DatasetError(f"{data_dir / info['labels']}: shape {labels.shape}, expected {expected[:2]} with classes 0..8")
    rows = [w for w in index["windows"] if w["split"] == name]
    rows.sort(key=lambda w: w["row"])
    episodes = np.array([w["episode"] for w in rows], dtype=np.int64)
    if len(episodes) != expected[0]:
        raise DatasetError(f"{data_dir / 'index.json'}: {len(episodes)} windows listed for {name}, arrays hold {expected[0]}")
    return Split(name, images, labels.astype(np.int64), episodes, seen_steps(data_dir, info, expected, images))


def seen_steps(data_dir: Path, info: dict, expected: tuple, images: np.ndarray) -> np.ndarray:
    """`[N, T]`: from the localiser's positions (`*_positions.npy`, columns 2 and 3 finite where it
    saw the person), as `lidar-har evaluate` reads them; from the images in a dataset made before
    positions were written."""
    if "positions" not in info:
        return visible_steps(images)
    path = data_dir / info["positions"]
    positions = load_array(path)
    if positions.shape != (*expected[:2], 4) or positions.dtype != np.float32:
        raise DatasetError(f"{path}: shape {positions.shape} {positions.dtype}, expected {(*expected[:2], 4)} float32")
    return np.isfinite(positions[:, :, 2:]).all(axis=2)


def visible_steps(images: np.ndarray) -> np.ndarray:
    """`[N, T]` from `[N, T, S, S]` windows: whether each scan's image shows any of the person."""
    return (images > 0).any(axis=(2, 3))
