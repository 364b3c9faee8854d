#!/usr/bin/env bash
# The fixed-Lidar baseline against the moving robot at the sweep's reference settings
# (training/sweep.toml: 240 episodes of 40 s, dataset seed 21, person-centred Boolean grid at
# 8 cm, hidden 16, 2,500 steps at a constant learning rate), over several training seeds, so
# that the difference can be told from the spread between seeds (docs/training.md). About 5
# minutes per training on 2 quiet cores.
#
#   training/experiments/fixed_vs_moving.sh [OUT_DIR] [SEED ...]    (default: out/fixed_vs_moving 1 2)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)"
cd "$ROOT"
OUT="${1:-out/fixed_vs_moving}"
shift || true
[ $# -gt 0 ] || set -- 1 2
SEEDS=("$@")
export ORT_DYLIB_PATH="${ORT_DYLIB_PATH:-$ROOT/.deps/onnxruntime/libonnxruntime.so}"
export PYTHONPATH="$ROOT/training"
cargo build --release --locked --bin lidar-har
LIDAR_HAR="$ROOT/target/release/lidar-har"
mkdir -p "$OUT"
for lidar in moving fixed; do
    data="$OUT/$lidar/data"
    if [ ! -f "$data/index.json" ]; then
        extra=()
        [ "$lidar" = fixed ] && extra=(--fixed-lidar)
        "$LIDAR_HAR" dataset --scenes 'config/scenes/*.yaml' --held-out office --episodes 240 \
            --episode-seconds 40 --seed 21 --resolution 0.08 "${extra[@]}" --out "$data"
    fi
done
for seed in "${SEEDS[@]}"; do
    for lidar in moving fixed; do
        run="$OUT/$lidar/seed$seed"
        mkdir -p "$run"
        training/.venv/bin/python -m lidar_har_train.train --data "$OUT/$lidar/data" \
            --out "$run/model.onnx" --hidden 16 --encoder-channels 8 --batch 64 \
            --steps-per-epoch 100 --max-epochs 25 --patience 25 --time-budget-min 1000 \
            --lr 0.003 --lr-final 0.003 --val-fraction 0.08 --threads 2 --skip-test-eval \
            --seed "$seed" >"$run/train.log"
        "$LIDAR_HAR" evaluate --model "$run/model.onnx" --data "$OUT/$lidar/data" \
            --out "$run/eval" >"$run/eval.log"
        training/.venv/bin/python - "$run/eval/metrics.json" "$lidar" "$seed" <<'EOF'
import json, sys
metrics = json.load(open(sys.argv[1]))
unseen = metrics["splits"]["test_unseen"]["accuracy"]
episodes = metrics["per_episode"]
print(f"{sys.argv[2]:6s} seed {sys.argv[3]}: test {100 * metrics['accuracy']:.1f} %, unseen office "
      f"{100 * unseen:.1f} %, per test episode best {100 * episodes['best']['accuracy']:.1f} / median "
      f"{100 * episodes['median']:.1f} / worst {100 * episodes['worst']['accuracy']:.1f} %", flush=True)
EOF
    done
done
