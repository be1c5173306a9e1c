#!/usr/bin/env bash
# Remakes the shipped models (bags/models/, what `serve` and launch_params/
# load by default) from a clean clone with `train`'s default recipe and the
# current model-file format (architecture, input scales, training edges, the
# fraction of the targets explained), then scores each on 100 held-out
# trajectories beside the standing-still reference. What it prints (and
# OUT/summary.txt) is what bags/README.md quotes.
# Usage: scripts/make_models.sh [OUT (models-out)]
# MCGNODE=path/to/mcgnode uses that binary instead of building one.
set -euo pipefail
cd "$(dirname "$0")/.."
OUT="${1:-models-out}"
if [ -z "${MCGNODE:-}" ]; then
    cargo build --release -q
fi
M="${MCGNODE:-${CARGO_TARGET_DIR:-$PWD/target}/release/mcgnode}"
mkdir -p "$OUT" bags/models
: > "$OUT/summary.txt"
for sys in spring pendulum; do
    "$M" simulate --system "$sys" --particles 5 --trajectories 100 --seed 1 --out "$OUT/$sys-train.mcap"
    "$M" simulate --system "$sys" --particles 5 --trajectories 100 --seed 2 --out "$OUT/$sys-test.mcap"
    model="bags/models/${sys}5-mcgnode.json"
    /usr/bin/time -f "$sys: %e s wall, %U s user, %S s system (load before: $(cut -d' ' -f1-3 /proc/loadavg))" \
        -a -o "$OUT/times.txt" "$M" train --model mcgnode --data "$OUT/$sys-train.mcap" --out "$model" \
        2> "$OUT/$sys-train.log"
    grep -E "^(recipe|wrote|explains|warning)" "$OUT/$sys-train.log" | tee -a "$OUT/summary.txt"
    "$M" evaluate --model "$model" --bag "$OUT/$sys-test.mcap" --rows 11 | tee "$OUT/$sys-eval.txt" \
        | tee -a "$OUT/summary.txt"
done
cat "$OUT/times.txt" | tee -a "$OUT/summary.txt"
