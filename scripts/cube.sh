#!/usr/bin/env bash
# The README's peridynamic-cube recipe from a clean clone: simulate 10 training
# and 4 test trajectories of the 125-particle cube, train MCGNODE (batch 10,
# edge MLPs 16,16, lr 1e-2 stepped to 1e-3 after epoch 200, 300 epochs), and
# evaluate it and the "nothing moves" reference. Usage: scripts/cube.sh OUT
set -euo pipefail
OUT="${1:?usage: scripts/cube.sh OUT}"
cd "$(dirname "$0")/.."
cargo build --release -q
M="${CARGO_TARGET_DIR:-$PWD/target}/release/mcgnode"
mkdir -p "$OUT" && cd "$OUT"
"$M" simulate --system peridynamic --trajectories 10 --seed 1 --out train.mcap
"$M" simulate --system peridynamic --trajectories 4 --seed 2 --out test.mcap
time "$M" train --model mcgnode --data train.mcap --batch 10 --lr 1e-2 --lr-drop 200:1e-3 \
    --epochs 300 --block-hidden edge_em=16,16 --block-hidden edge_out=16,16 --out solid.json
for m in still solid.json; do
    "$M" evaluate --model "$m" --bag test.mcap --rows 11 | tee "eval-${m%.json}.txt"
done
