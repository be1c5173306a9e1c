#!/usr/bin/env bash
# The node's Plan service against `mcgnode bench`'s planning figure, side by
# side (a bench, not a test): one round of 256 random candidates, each 5
# control steps of 10 integration steps (50 steps), through an MCGNODE of a
# 20-particle held chain, as `bench --only plan` times it in-process. Makes
# the model (`simulate` + 1 epoch of `train`, with the bench model's
# architecture: `--recipe paper --body-force off`; the weights do not change
# a step's cost), runs `mcgnode serve` with it (dt 0.01, substeps 10: the
# bench's integration step 0.001) and scripts/ros/bench_plan.py in a private
# network namespace, interleaved with `mcgnode bench --only plan`, and prints
# both medians with the load.
#
#     scripts/ros_bench_plan.sh [--rounds 3] [--calls 20]
#
# Needs the release binary (BIN=path overrides) and the rclpy venv
# (scripts/setup_venv.sh; the interface package is built here).
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
cd "$ROOT"
rounds=3 calls=20
while [ $# -gt 0 ]; do
    case "$1" in
    --rounds) rounds="$2"; shift 2 ;;
    --calls) calls="$2"; shift 2 ;;
    -h | --help) sed -n '2,16p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "ros_bench_plan.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
    esac
done
BIN="${BIN:-${CARGO_TARGET_DIR:-$ROOT/target}/release/mcgnode}"
[ -x "$BIN" ] || { echo "error: $BIN missing; run: cargo build --release" >&2; exit 1; }
scripts/build_msgs.sh >/dev/null
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
"$BIN" simulate --system held-chain --particles 19 --trajectories 4 --states 11 \
    --out "$work/chain.mcap" >/dev/null
"$BIN" train --model mcgnode --data "$work/chain.mcap" --epochs 1 --recipe paper --body-force off --out "$work/model.json" \
    >/dev/null 2>&1
# The request: the bench's target, cost and sampler (the start: the bag's first state).
cat >"$work/request.json" <<'JSON'
{"particles": [18], "targets": [{"x": 1.0, "y": -20.0, "z": 0.0}], "cost": "final", "effort": 0.001,
 "horizon": 5, "sampler": "random", "candidates": 256, "iterations": 1, "sigma": 0.5, "max_speed": 1.0}
JSON
printf 'mcgnode:\n  ros__parameters:\n    model: %s\n    dt: 0.01\n    substeps: 10\n    horizon: 5\n' \
    "$work/model.json" >"$work/params.yaml"
export BIN WORK="$work" CALLS="$calls" ENV_SH="$ROOT/build/msgs/env.sh"
for r in $(seq "$rounds"); do
    echo "round $r: load $(cut -d' ' -f1-3 /proc/loadavg)"
    "$BIN" bench --only plan --json >"$work/bench.json"
    python3 -c 'import json,sys; f=json.load(open(sys.argv[1]))[0]; print("  bench --only plan: median %.1f ms" % (1e3 * f["value"]))' "$work/bench.json"
    timeout 300 scripts/netns.sh bash -c '
        . "$ENV_SH"
        "$BIN" serve --params "$WORK/params.yaml" 2>"$WORK/node.log" &
        node=$!
        for _ in $(seq 200); do grep -q serving "$WORK/node.log" && break; sleep 0.05; done
        python3 scripts/ros/bench_plan.py --request "$WORK/request.json" --bag "$WORK/chain.mcap" --calls "$CALLS"
        rc=$?
        kill -INT $node
        for _ in $(seq 50); do kill -0 $node 2>/dev/null || break; sleep 0.1; done
        kill -0 $node 2>/dev/null && kill -KILL $node
        wait $node
        exit $rc
    ' | sed -n 's/^PLAN_BENCH /  node Plan service: /p; s/^FAIL/  FAIL/p'
done
echo "machine: $(nproc) cores, $(uname -sr); mcgnode $(git rev-parse --short HEAD 2>/dev/null || echo '?')"
