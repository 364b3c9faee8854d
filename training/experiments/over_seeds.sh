#!/usr/bin/env bash
# Sweep configurations retrained over several training seeds, so that a difference between
# two can be told from the spread between seeds of one (docs/training.md, session 10). The
# sweep's reference settings (training/sweep.toml: 240 episodes of 40 s, dataset seed 21,
# person-centred Boolean grid at 8 cm, 32 px, hidden 16, 2,500 steps at a constant learning
# rate), with one change per variant:
#   reference   the moving robot, as above
#   fixed       a fixed Lidar at a random free spot per episode
#   room_fixed  room-fixed framing
#   wide        hidden 32, encoder 16
# About 5 minutes per training on 2 quiet cores (wide: 8).
#
#   training/experiments/over_seeds.sh OUT_DIR VARIANT[,VARIANT...] SEED [SEED ...]
#   e.g. training/experiments/over_seeds.sh out/over_seeds reference,fixed 1 2 3
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$ROOT"
if [ $# -lt 3 ]; then
    sed -n '2,14p' "$0" | sed 's/^# \{0,1\}//' >&2
    exit 2
fi
OUT="$1"
IFS=, read -r -a VARIANTS <<<"$2"
shift 2
export ORT_DYLIB_PATH="${ORT_DYLIB_PATH:-$ROOT/.deps/onnxruntime/libonnxruntime.so}"
export PYTHONPATH="$ROOT/training"
cargo build --release --locked --bin lidar-har
LIDAR_HAR="$ROOT/target/release/lidar-har"

for variant in "${VARIANTS[@]}"; do
    data="$OUT/data-reference" data_flags=() model_flags=(--hidden 16 --encoder-channels 8)
    case "$variant" in
    reference) ;;
    fixed) data="$OUT/data-fixed" data_flags=(--fixed-lidar) ;;
    room_fixed) data="$OUT/data-room_fixed" data_flags=(--framing room_fixed) ;;
    wide) model_flags=(--hidden 32 --encoder-channels 16) ;;
    *) echo "over_seeds: unknown variant '$variant' (reference, fixed, room_fixed, wide)" >&2; exit 2 ;;
    esac
    if [ ! -f "$data/index.json" ]; then
        "$LIDAR_HAR" dataset --scenes 'config/scenes/*.yaml' --held-out office --episodes 240 \
            --episode-seconds 40 --seed 21 --resolution 0.08 "${data_flags[@]}" --out "$data" >"$data.log" 2>&1
    fi
    for seed in "$@"; do
        run="$OUT/$variant/seed$seed"
        mkdir -p "$run"
        training/.venv/bin/python -m lidar_har_train.train --data "$data" --out "$run/model.onnx" \
            "${model_flags[@]}" --batch 64 --steps-per-epoch 100 --max-epochs 25 --patience 25 \
            --time-budget-min 1000 --lr 0.003 --lr-final 0.003 --val-fraction 0.08 --threads 2 \
            --skip-test-eval --seed "$seed" >"$run/train.log"
        "$LIDAR_HAR" evaluate --model "$run/model.onnx" --data "$data" --out "$run/eval" >"$run/eval.log"
        training/.venv/bin/python - "$run/eval/metrics.json" "$variant" "$seed" <<'EOF'
import json, sys
metrics = json.load(open(sys.argv[1]))
unseen = metrics["splits"]["test_unseen"]["accuracy"]
episodes = metrics["per_episode"]
print(f"{sys.argv[2]:10s} seed {sys.argv[3]}: test {100 * metrics['accuracy']:.1f} %, unseen office "
      f"{100 * unseen:.1f} %, per test episode best {100 * episodes['best']['accuracy']:.1f} / median "
      f"{100 * episodes['median']:.1f} / worst {100 * episodes['worst']['accuracy']:.1f} %", flush=True)
EOF
    done
done
