"""Whether the published pelvis of a still body is off now and then or all the time. Groups
the seen scans of one activity (default lying_down) into spells: one run, the same true
activity, no gap over 0.5 s, the true pelvis within 0.3 m of where the spell began. Then
prints the error by time into the spell, and the spells holding the most scans off by more
than the threshold: a spell off on nearly every scan is a view that more scans of the same
kind will not mend. Reads the JSON lines of `localiser_accuracy --dump-points` run with
`--classifier-config` (docs/localiser.md, "Accuracy"):

    cargo run --release -p lidar-har-pipeline --example localiser_accuracy -- --seeds 3 \\
        --classifier-config config/classifier.yaml --dump-points out/points.jsonl
    training/.venv/bin/python scripts/pelvis_spells.py out/points.jsonl [ACTIVITY [THRESHOLD_M]]
"""
import argparse
import json
import sys

import numpy as np

MAX_GAP_NS = 500_000_000
STILL_M = 0.3


def spells_of(rows: list[dict], activity: str) -> list[list[dict]]:
    spells: list[list[dict]] = []
    for row in rows:
        if row["activity"] != activity or row.get("published") is None:
            continue
        last = spells[-1][-1] if spells else None
        if (
            last is not None
            and last["run"] == row["run"]
            and 0 <= row["stamp_ns"] - last["stamp_ns"] <= MAX_GAP_NS
            and np.hypot(*np.subtract(row["pelvis"][:2], spells[-1][0]["pelvis"][:2])) <= STILL_M
        ):
            spells[-1].append(row)
        else:
            spells.append([row])
    return spells


def parse_args() -> argparse.Namespace:
    """argparse, so that `--help` prints the usage instead of being opened as the file."""
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument(
        "points", metavar="POINTS.jsonl", help="the JSON lines of localiser_accuracy --dump-points"
    )
    parser.add_argument(
        "activity",
        metavar="ACTIVITY",
        nargs="?",
        default="lying_down",
        help="the true activity whose spells are grouped (default lying_down)",
    )
    parser.add_argument(
        "threshold",
        metavar="THRESHOLD_M",
        nargs="?",
        type=float,
        default=0.3,
        help="how far from the true pelvis a published one is off, metres (default 0.3)",
    )
    return parser.parse_args()


def main() -> None:
    args = parse_args()
    activity, threshold = args.activity, args.threshold
    try:
        with open(args.points) as points:
            rows = [json.loads(line) for line in points]
    except (OSError, json.JSONDecodeError) as e:
        sys.exit(f"{args.points}: {e}")
    if rows and not {"run", "stamp_ns"} <= rows[0].keys():
        sys.exit(f"{args.points}: no run or stamp_ns; dump again with this tree's example")
    # A dump made without the classifier has `"published": null` on every row.
    if rows and all(row.get("published") is None for row in rows):
        sys.exit(f"{args.points}: no published pelvis; dump with --classifier-config")
    spells = spells_of(rows, activity)
    if not spells:
        sys.exit(f"{args.points}: no seen scans of {activity} with a published pelvis")

    def error(row: dict) -> float:
        return float(np.hypot(*np.subtract(row["published"], row["pelvis"][:2])))

    errors = [np.array([error(r) for r in spell]) for spell in spells]
    into = [np.array([(r["stamp_ns"] - spell[0]["stamp_ns"]) / 1e9 for r in spell]) for spell in spells]
    all_errors = np.concatenate(errors)
    off = int((all_errors > threshold).sum())
    print(
        f"{activity}: {len(all_errors)} seen scans in {len(spells)} spells; published pelvis "
        f"median {np.median(all_errors):.3f} m, p95 {np.percentile(all_errors, 95):.3f} m, "
        f"{off} scans ({off / len(all_errors):.1%}) more than {threshold} m off"
    )
    print("by time into the spell: scans, median, p95, share off")
    for start, end in [(0, 1), (1, 2), (2, 4), (4, 8), (8, np.inf)]:
        e = np.concatenate([err[(t >= start) & (t < end)] for err, t in zip(errors, into)])
        if len(e):
            print(
                f"  {start}-{end} s: {len(e):6d}  {np.median(e):.3f}  "
                f"{np.percentile(e, 95):.3f}  {(e > threshold).mean():.1%}"
            )
    order = sorted(range(len(spells)), key=lambda i: -(errors[i] > threshold).sum())
    print(
        "spells by scans off: run, scans, share off, median error, mean error (along the line "
        "of sight, across it), median range to the Lidar, median points, cumulative share of "
        "the scans off"
    )
    cumulative = 0
    for i in order:
        bad = int((errors[i] > threshold).sum())
        if bad == 0 or cumulative >= 0.9 * off:
            break
        cumulative += bad
        spell = spells[i]
        offset = np.array([np.subtract(r["published"], r["pelvis"][:2]) for r in spell])
        sight = np.array([np.subtract(r["pelvis"][:2], r["laser"]) for r in spell])
        distance = np.linalg.norm(sight, axis=1)
        sight /= np.maximum(distance, 1e-9)[:, None]
        along = (offset * sight).sum(axis=1)
        across = offset[:, 0] * -sight[:, 1] + offset[:, 1] * sight[:, 0]
        print(
            f"  {spell[0]['run']:28s} {len(spell):5d}  {bad / len(spell):4.0%}  "
            f"{np.median(errors[i]):.2f} m  ({along.mean():+.2f}, {across.mean():+.2f}) m  "
            f"{np.median(distance):.2f} m  {np.median([len(r['points']) for r in spell]):4.0f}  "
            f"{cumulative / off:4.0%}"
        )


if __name__ == "__main__":
    main()
