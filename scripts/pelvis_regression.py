"""Can a learned per-scan correction place the hidden pelvis better than the localiser does?
Fits gradient-boosted trees (scikit-learn) from the shape of the person's returns in one scan
(spread, main axis, a 12 x 12 occupancy grid at 0.1 m around the estimate, the tracked
velocity, all in the frame of the Lidar's line of sight) to the pelvis's offset from the
localiser's estimate, on half of the rooms, and scores it on the other half, then the other
way round: rooms the correction never saw. Prints the error median / p95 before and after,
overall and per activity. Reads the JSON lines of `localiser_accuracy --dump-points`
(docs/localiser.md, "Accuracy"); a study, not part of the product (needs `pip install
scikit-learn`):

    cargo run --release -p lidar-har-pipeline --example localiser_accuracy -- --seeds 3 \\
        --dump-points out/pelvis/test.jsonl
    python scripts/pelvis_regression.py out/pelvis/test.jsonl

(The random rooms of `lidar-har random-scenes` cannot serve as training data here: their
person only stands until `lidar-har dataset` gives them a script.)
"""
import argparse
import json

import numpy as np
from sklearn.ensemble import HistGradientBoostingRegressor

GRID = 12
CELL_M = 0.1
ACTIVITIES = ["walking", "standing", "lying_down", "sitting_on_floor", "crawling", "getting_up"]


def scan_features(row: dict) -> tuple[list[float], np.ndarray]:
    """Features of one scan, and the pelvis's offset from the estimate, in the frame of the
    line of sight (x from the Lidar through the estimate)."""
    estimate = np.array(row["reported"])
    sight = estimate - np.array(row["laser"])
    distance = float(np.linalg.norm(sight))
    ux = sight / max(distance, 1e-9)
    to_sight = np.stack([ux, [-ux[1], ux[0]]])
    points = (np.array(row["points"]).reshape(-1, 2) - estimate) @ to_sight.T
    n = len(points)
    features = [n, np.log1p(n), distance]
    features += [*points.mean(0), *points.std(0), *points.min(0), *points.max(0)]
    if n >= 2:
        eigenvalues, vectors = np.linalg.eigh(np.cov(points.T) + 1e-9 * np.eye(2))
        axis, across = vectors[:, 1], vectors[:, 0]
        angle = np.arctan2(axis[1], axis[0])
        along, side = points @ axis, points @ across
        features += [eigenvalues[1], eigenvalues[0], np.cos(2 * angle), np.sin(2 * angle),
                     np.ptp(along), np.ptp(side)]
    else:
        features += [0.0, 0.0, 1.0, 0.0, 0.0, 0.0]
    velocity = np.array(row["velocity"])
    features += [*(to_sight @ velocity), float(np.linalg.norm(velocity))]
    grid = np.zeros((GRID, GRID))
    cells = np.floor(points / CELL_M + GRID / 2).astype(int)
    inside = (cells >= 0).all(1) & (cells < GRID).all(1)
    np.add.at(grid, (cells[inside, 0], cells[inside, 1]), 1)
    features += list(grid.ravel())
    target = to_sight @ (np.array(row["pelvis"][:2]) - estimate)
    return features, target


def load(path: str) -> dict[str, np.ndarray]:
    rows = [json.loads(line) for line in open(path)]
    pairs = [scan_features(r) for r in rows]
    return {
        "x": np.array([f for f, _ in pairs], float),
        "y": np.array([t for _, t in pairs]),
        "activity": np.array([r["activity"] for r in rows]),
        "scene": np.array([r["scene"] for r in rows]),
    }


def fit_predict(train: dict, x: np.ndarray) -> np.ndarray:
    prediction = np.zeros((len(x), 2))
    for k in range(2):
        model = HistGradientBoostingRegressor(max_iter=300, loss="absolute_error", random_state=0)
        model.fit(train["x"], train["y"][:, k])
        prediction[:, k] = model.predict(x)
    return prediction


def report(name: str, offset: np.ndarray, truth: np.ndarray, activity: np.ndarray) -> None:
    error = np.linalg.norm(truth - offset, axis=1)
    line = f"{name:24s} all {np.median(error):.3f} / {np.percentile(error, 95):.3f} m"
    for a in ACTIVITIES:
        k = activity == a
        if k.any():
            line += f" | {a} {np.median(error[k]):.3f} / {np.percentile(error[k], 95):.3f}"
    print(line, flush=True)


def subset(data: dict, mask: np.ndarray) -> dict:
    return {key: value[mask] for key, value in data.items()}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("dump", help="POINTS.jsonl of `localiser_accuracy --dump-points`")
    data = load(parser.parse_args().dump)
    names = sorted(set(data["scene"]))
    half = np.isin(data["scene"], names[::2])
    print("pelvis error, median / p95 (m): the localiser's estimate, then corrected")
    for train, test in [(subset(data, half), subset(data, ~half)), (subset(data, ~half), subset(data, half))]:
        print(f"fit on {len(train['x'])} scans ({', '.join(sorted(set(train['scene'])))}), "
              f"scored on {len(test['x'])} ({', '.join(sorted(set(test['scene'])))})")
        report("localiser", np.zeros_like(test["y"]), test["y"], test["activity"])
        report("+ learned correction", fit_predict(train, test["x"]), test["y"], test["activity"])


if __name__ == "__main__":
    main()
