#!/usr/bin/env bash
# The pose head's offset loss against the tail of its error (docs/training.md, session 37):
# one fresh dataset (the committed head's recipe: the drawn rooms and 150 random rooms, the
# office held out), then four heads fitted side by side on the committed activity model,
# and the committed head scored on the same splits:
#   a  smooth L1, beta 0.05 (the committed head's settings: the control)
#   b  beta 0.3
#   c  beta 1.0 (close to a squared error for the errors that matter)
#   d  beta 0.05, from 10 scans of history instead of 12 (--first-step 9)
# Sized for a GPU machine (session 37: an H200 with 16 cores, 377 s with MINUTES 4); on 2
# cores use a few hundred episodes and DEVICE cpu. The dataset lives in WORK (11 GB at 6000
# episodes); every log, score (JSON) and head (ONNX) goes to OUT_DIR.
#
#   training/experiments/pose_head_loss.sh OUT_DIR EPISODES MINUTES THREADS_PER_FIT DEVICE
#   e.g. training/experiments/pose_head_loss.sh out/loss37 6000 4 4 cuda
# Environment: LIDAR_HAR (the binary; default target/release/lidar-har), PYTHON (default
# training/.venv/bin/python, else python3), WORK (default /tmp/pose_head_loss).
set -uo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$ROOT"
if [ $# -ne 5 ]; then
    sed -n '2,18p' "$0" | sed 's/^# \{0,1\}//' >&2
    exit 2
fi
OUT=$1 EPISODES=$2 MINUTES=$3 THREADS=$4 DEVICE=$5
LIDAR_HAR=${LIDAR_HAR:-target/release/lidar-har}
PYTHON=${PYTHON:-$([ -x training/.venv/bin/python ] && echo training/.venv/bin/python || echo python3)}
WORK=${WORK:-/tmp/pose_head_loss}
mkdir -p "$WORK" "$OUT"
start=$(date +%s)
say() { echo "[$(( $(date +%s) - start )) s] $*"; }

"$LIDAR_HAR" random-scenes --count 150 --seed 1 --out "$WORK/rooms150" > /dev/null || exit 1
"$LIDAR_HAR" dataset --scenes 'config/scenes/*.yaml' "$WORK/rooms150/*.yaml" --held-out office \
    --episodes "$EPISODES" --episode-seconds 40 --seed 93 --resolution 0.08 --framing room_fixed \
    --test-fraction 0.1 --threads "$(nproc)" --out "$WORK/pose93" > "$OUT/dataset.log" 2>&1 \
    || { tail -20 "$OUT/dataset.log"; exit 1; }
say "dataset: $(tail -1 "$OUT/dataset.log")"

export PYTHONPATH=training PYTHONUNBUFFERED=1
fit() { # NAME, then pose_head options
    local name=$1
    shift
    "$PYTHON" -m lidar_har_train.pose_head models/activity.onnx "$WORK/pose93" --out "$OUT/head_$name.onnx" \
        --device "$DEVICE" --threads "$THREADS" --minutes "$MINUTES" --seed 3 --json "$OUT/$name.json" "$@" \
        > "$OUT/$name.log" 2>&1
    say "$name: exit $?"
}
fit a --beta 0.05 &
fit b --beta 0.3 &
fit c --beta 1.0 &
fit d --beta 0.05 --first-step 9 &
"$PYTHON" -m lidar_har_train.pose_head models/activity.onnx "$WORK/pose93" --head models/pose_head.onnx \
    --device "$DEVICE" --threads 2 --json "$OUT/committed.json" > "$OUT/committed.log" 2>&1
say "committed: exit $?"
wait
for name in committed a b c d; do
    echo "== $name"
    grep -E "^(test|test_unseen):|head used|wrote|Error" "$OUT/$name.log"
done
