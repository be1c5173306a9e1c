#!/usr/bin/env bash
# The README's peridynamic-cube table from a clean clone: simulate 10 training
# and 4 test trajectories of the 125-particle cube, train MCGNODE (batch 10,
# lr 1e-2 for 300 epochs, continued to 2,000, then 500 epochs at lr 1e-3) and
# evaluate each stage and the "nothing moves" reference. About 20 minutes on
# 2 cores. Usage: scripts/cube.sh OUT
set -euo pipefail
OUT="${1:?usage: scripts/cube.sh OUT}"
cd "$(dirname "$0")/.."
cargo build --release -q
M="$PWD/target/release/mcgnode"
mkdir -p "$OUT" && cd "$OUT"
"$M" simulate --system peridynamic --trajectories 10 --seed 1 --out train.mcap
"$M" simulate --system peridynamic --trajectories 4 --seed 2 --out test.mcap
"$M" train --model mcgnode --data train.mcap --batch 10 --lr 1e-2 --epochs 300 --out cube-300.json
"$M" train --model mcgnode --data train.mcap --batch 10 --lr 1e-2 --epochs 1700 --init cube-300.json --out cube-2000.json
"$M" train --model mcgnode --data train.mcap --batch 10 --lr 1e-3 --epochs 500 --init cube-2000.json --out cube-2500.json
for m in still cube-300.json cube-2000.json cube-2500.json; do
    "$M" evaluate --model "$m" --bag test.mcap --rows 11 | tee "eval-${m%.json}.txt"
done
