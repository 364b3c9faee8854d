"""Where the pelvis lies from the localiser's estimate, in the body's own frame, per activity;
how far it is from anything the Lidar returned from the person; and what a constant lead along
the tracked velocity would do to the error; and an upper bound for any body model that moves
the estimate by a fixed offset in the body's frame (an oracle told the true activity and
heading, with each activity's median offset). Reads the JSON
lines of `localiser_accuracy --dump-points` (docs/localiser.md, "Accuracy"):

    cargo run --release -p lidar-har-pipeline --example localiser_accuracy -- --seeds 3 \\
        --dump-points out/points.jsonl
    .venv/bin/python scripts/pelvis_offsets.py out/points.jsonl
"""
import json
import sys

import numpy as np


def main() -> None:
    if len(sys.argv) != 2:
        sys.exit(f"usage: {sys.argv[0]} POINTS.jsonl")
    try:
        with open(sys.argv[1]) as points:
            rows = [json.loads(line) for line in points]
    except (OSError, json.JSONDecodeError) as e:
        sys.exit(f"{sys.argv[1]}: {e}")
    if not rows:
        sys.exit(f"{sys.argv[1]}: no seen scans")
    fields = {"activity", "pelvis", "reported", "velocity", "points"}
    missing = [r for r in rows if not isinstance(r, dict) or not fields <= r.keys()]
    if missing:
        sys.exit(f"{sys.argv[1]}: {len(missing)} of {len(rows)} lines lack one of {', '.join(sorted(fields))}; "
                 "dump them with localiser_accuracy --dump-points")
    activity = np.array([r["activity"] for r in rows])
    pelvis = np.array([r["pelvis"] for r in rows])  # x, y, heading
    reported = np.array([r["reported"] for r in rows])
    velocity = np.array([r["velocity"] for r in rows])
    error = pelvis[:, :2] - reported
    heading = pelvis[:, 2]
    forward = error[:, 0] * np.cos(heading) + error[:, 1] * np.sin(heading)
    left = -error[:, 0] * np.sin(heading) + error[:, 1] * np.cos(heading)
    speed = np.hypot(velocity[:, 0], velocity[:, 1])
    unit = velocity / np.maximum(speed, 1e-9)[:, None]
    agreement = unit[:, 0] * np.cos(heading) + unit[:, 1] * np.sin(heading)

    print(f"{len(rows)} scans with the person seen; pelvis - estimate in the body's frame (median, m)")
    for name in sorted(set(activity)):
        k = activity == name
        moving = k & (speed >= 0.2)
        print(f"{name:20s} {k.sum():6d} scans: forward {np.median(forward[k]):+.3f} left {np.median(left[k]):+.3f} "
              f"|error| {np.median(np.hypot(forward[k], left[k])):.3f}; velocity along the heading, median cosine "
              f"{np.median(agreement[moving]) if moving.any() else float('nan'):.2f} ({moving.sum()} scans >= 0.2 m/s)")

    nearest = np.array([np.min(np.hypot(*(np.array(r["points"]) - p[:2]).T)) for r, p in zip(rows, pelvis)])
    print(f"the pelvis's distance to the nearest of the person's returns: median {np.median(nearest):.3f} m, "
          f"p95 {np.percentile(nearest, 95):.3f} m, over 0.3 m in {100 * np.mean(nearest > 0.3):.1f} % of the scans")

    print("a constant lead along the tracked velocity at >= 0.3 m/s: overall error median / p95")
    for lead in (0.0, 0.03, 0.06, 0.09):
        estimate = reported + np.where((speed >= 0.3)[:, None], lead * unit, 0.0)
        distance = np.hypot(*(pelvis[:, :2] - estimate).T)
        walking = distance[activity == "walking"]
        print(f"lead {lead:.2f} m: {np.median(distance):.4f} / {np.percentile(distance, 95):.3f} m "
              f"(walking median {np.median(walking):.3f} m)")


    print("oracle: the true activity and heading, each activity's median offset in the body's frame "
          "(the best a fixed-offset body model could do), error median / p95 before -> after")
    before = np.hypot(forward, left)
    after = np.empty_like(before)
    for name in sorted(set(activity)):
        k = activity == name
        after[k] = np.hypot(forward[k] - np.median(forward[k]), left[k] - np.median(left[k]))
        print(f"{name:20s} {np.median(before[k]):.3f} / {np.percentile(before[k], 95):.3f} -> "
              f"{np.median(after[k]):.3f} / {np.percentile(after[k], 95):.3f} m")
    print(f"{'overall':20s} {np.median(before):.3f} / {np.percentile(before, 95):.3f} -> "
          f"{np.median(after):.3f} / {np.percentile(after, 95):.3f} m")


if __name__ == "__main__":
    main()
