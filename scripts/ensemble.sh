#!/usr/bin/env bash
# Calibration of an ensemble's spread: trains K members of MCGNODE (with
# --edge-physics, so that it reads other stiffnesses) on 5-spring rings, then
# evaluates it on held-out rings: in range (another seed), with stiffness 2x,
# and with starting velocities 3x, each alone and all together. Prints per
# test set the mean spread and error at lead 1 s, the Spearman rank
# correlation between spread and error at 1 s over the starts, and the
# fraction of states whose error lies within two spreads.
#
#   scripts/ensemble.sh [OUT_DIR]     # bags and the model in OUT_DIR (default: a temporary folder)
#
# Environment: MCGNODE (the binary; default target/release/mcgnode, built if
# missing), K (members, default 5), TRAIN (training trajectories, default
# 100), EPOCHS (default: the recipe's), TEST (trajectories per test set,
# default 20).
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${MCGNODE:-target/release/mcgnode}
[ -x "$BIN" ] || cargo build --release --quiet
BIN=$(realpath "$BIN")
OUT=${1:-$(mktemp -d)}
mkdir -p "$OUT"
K=${K:-5}
TRAIN=${TRAIN:-100}
TEST=${TEST:-20}
EPOCHS_ARG=()
[ -n "${EPOCHS:-}" ] && EPOCHS_ARG=(--epochs "$EPOCHS")

cd "$OUT"
"$BIN" simulate --system spring --particles 5 --trajectories "$TRAIN" --seed 1 --out train.mcap
"$BIN" simulate --system spring --particles 5 --trajectories "$TEST" --seed 2 --states 21 --out in-range.mcap
"$BIN" simulate --system spring --particles 5 --trajectories "$TEST" --seed 3 --states 21 --stiffness 2 --out stiffness-2x.mcap
"$BIN" simulate --system spring --particles 5 --trajectories "$TEST" --seed 4 --states 21 --velocity-scale 3 --out velocity-3x.mcap
start=$(date +%s.%N)
"$BIN" train --model mcgnode --edge-physics --ensemble "$K" "${EPOCHS_ARG[@]}" --data train.mcap --out ensemble.json --quiet
echo "trained $K members in $(python3 -c "print(round($(date +%s.%N) - $start, 1))") s"

for set in in-range stiffness-2x velocity-3x; do
    "$BIN" evaluate --json --model ensemble.json --bag "$set.mcap" >"$set.json" 2>/dev/null
done
echo "| system | test set | starts | spread at 1 s | error at 1 s | Spearman at 1 s | within 2 spreads |"
echo "| --- | --- | --- | --- | --- | --- | --- |"
# One row per test set, then the three pooled: Spearman over all their
# starts (ties by average rank) and the within-2-spreads fraction weighted
# by starts (every set has the same states per start).
python3 - in-range stiffness-2x velocity-3x <<'PY'
import json, sys

def ranks(x):
    order = sorted(range(len(x)), key=lambda i: x[i])
    r, i = [0.0] * len(x), 0
    while i < len(order):
        j = i
        while j + 1 < len(order) and x[order[j + 1]] == x[order[i]]:
            j += 1
        for k in order[i:j + 1]:
            r[k] = (i + j) / 2 + 1
        i = j + 1
    return r

def spearman(a, b):
    ra, rb = ranks(a), ranks(b)
    n = len(a)
    ma, mb = sum(ra) / n, sum(rb) / n
    sab = sum((x - ma) * (y - mb) for x, y in zip(ra, rb))
    saa = sum((x - ma) ** 2 for x in ra)
    sbb = sum((y - mb) ** 2 for y in rb)
    return sab / (saa * sbb) ** 0.5 if saa > 0 and sbb > 0 else None

f = lambda x: "n/a" if x is None else "%.2f" % x
e = lambda x: "%.2e" % x
pairs, within, starts = [], 0.0, 0
for name in sys.argv[1:]:
    c = json.load(open(name + ".json"))["calibration"]
    p = c["spread_error_1s"]
    pairs += p
    within += (c["within_2_spreads"] or 0.0) * c["starts"]
    starts += c["starts"]
    s1 = sum(x[0] for x in p) / max(len(p), 1)
    e1 = sum(x[1] for x in p) / max(len(p), 1)
    print("| spring | %s | %d | %s | %s | %s | %s |" % (name, c["starts"], e(s1), e(e1),
          f(c["spearman_spread_error_1s"]), f(c["within_2_spreads"])))
s1 = sum(x[0] for x in pairs) / len(pairs)
e1 = sum(x[1] for x in pairs) / len(pairs)
rho = spearman([x[0] for x in pairs], [x[1] for x in pairs])
print("| spring | all three | %d | %s | %s | %s | %s |" % (starts, e(s1), e(e1), f(rho),
      f(within / starts)))
PY
