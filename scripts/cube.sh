#!/usr/bin/env bash
# The README's peridynamic-cube recipe from a clean clone: simulate training and
# 4 test trajectories of the 125-particle cube, train each model with the same
# recipe (batch 10, lr 1e-2 stepped to 1e-3 after epoch 200, 300 epochs; the
# GNODE family also with wider edge MLPs, 16,16), and evaluate it and the "nothing
# moves" reference. Training wall, user and system times go to times.txt.
# Usage: scripts/cube.sh OUT [TRAINING_TRAJECTORIES (10)] [MODEL ... (mcgnode)]
# MCGNODE=path/to/mcgnode uses that binary instead of building one; EPOCHS=N
# trains N epochs instead of 300, the rate stepped down after two thirds of them.
set -euo pipefail
OUT="${1:?usage: scripts/cube.sh OUT [TRAJECTORIES] [MODEL ...]}"
TRAJ="${2:-10}"
shift $(( $# < 2 ? $# : 2 ))
MODELS=("${@:-mcgnode}")
EPOCHS="${EPOCHS:-300}"
DROP=$(( EPOCHS * 2 / 3 ))
cd "$(dirname "$0")/.."
if [ -z "${MCGNODE:-}" ]; then
    cargo build --release -q
fi
M="${MCGNODE:-${CARGO_TARGET_DIR:-$PWD/target}/release/mcgnode}"
mkdir -p "$OUT" && cd "$OUT"
"$M" simulate --system peridynamic --trajectories "$TRAJ" --seed 1 --out train.mcap
"$M" simulate --system peridynamic --trajectories 4 --seed 2 --out test.mcap
"$M" evaluate --model still --bag test.mcap --rows 11 | tee eval-still.txt
for model in "${MODELS[@]}"; do
    extra=()
    # Wider edge MLPs where bonds are embedded and decoded (GNODE-style
    # variants decode per node), as reproduce's peri_opts.
    case "$model" in
        lgn|hgn|gns) ;;
        mcgnode) extra=(--block-hidden edge_em=16,16 --block-hidden edge_out=16,16) ;;
        *) extra=(--block-hidden edge_em=16,16 --block-hidden node_out=16,16) ;;
    esac
    start=$(date +%s.%N)
    /usr/bin/time -f "$model: %e s wall, %U s user, %S s system (load before: $(cut -d' ' -f1-3 /proc/loadavg))" \
        -a -o times.txt "$M" train --model "$model" --data train.mcap --batch 10 --lr 1e-2 \
        --lr-drop "$DROP:1e-3" --epochs "$EPOCHS" "${extra[@]}" --out "$model.json" --quiet
    echo "$model trained in $(echo "$(date +%s.%N) - $start" | bc) s"
    "$M" evaluate --model "$model.json" --bag test.mcap --rows 11 | tee "eval-$model.txt"
done
cat times.txt
