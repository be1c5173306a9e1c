#!/usr/bin/env bash
# Latency and throughput of the ROS 2 node against rclpy (a bench, not a test).
# Runs `mcgnode serve` (shipped 5-spring MCGNODE model, horizon 100) and
# scripts/ros/bench_node.py together in a private network namespace
# (scripts/netns.sh), then prints a small report:
#   (a) publish -> 100-step prediction latency, p50/p99 over --messages states
#       sent one at a time;
#   (b) --rate Hz of input for --duration s: messages the node dropped (its
#       NodeDiagnostics counters against what was sent) and its VmRSS over time.
#
#     scripts/ros_bench.sh [--duration 60] [--messages 1000] [--rate 1000]
#                          [--model bags/models/spring5-mcgnode.json] [--horizon 100]
#                          [--keep-trajectory-subscriber] [--out report.json]
#
# Needs the release binary (cargo build --release; $CARGO_TARGET_DIR is honoured,
# BIN=path overrides) and the rclpy venv
# (scripts/setup_venv.sh; the interface package is built here).
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
cd "$ROOT"

duration=60 messages=1000 rate=1000 horizon=100 out="" extra=()
model=bags/models/spring5-mcgnode.json
while [ $# -gt 0 ]; do
    case "$1" in
    --duration) duration="$2"; shift 2 ;;
    --messages) messages="$2"; shift 2 ;;
    --rate) rate="$2"; shift 2 ;;
    --model) model="$2"; shift 2 ;;
    --horizon) horizon="$2"; shift 2 ;;
    --out) out="$2"; shift 2 ;;
    --keep-trajectory-subscriber) extra+=("$1"); shift ;;
    -h | --help) sed -n '2,17p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "ros_bench.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
    esac
done

BIN="${BIN:-${CARGO_TARGET_DIR:-$ROOT/target}/release/mcgnode}"
[ -x "$BIN" ] || { echo "error: $BIN missing; run: cargo build --release" >&2; exit 1; }
[ -e "$model" ] || [[ "$model" == truth:* ]] || { echo "error: model $model not found" >&2; exit 1; }
scripts/build_msgs.sh >/dev/null
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

# The node and the bench share one namespace; the node is stopped with SIGINT
# (and killed if it ignores it) whatever the bench's outcome.
export BIN MODEL="$model" HORIZON="$horizon" LOG="$work/node.log" ENV_SH="$ROOT/build/msgs/env.sh"
export BENCH_ARGS="--messages $messages --rate $rate --duration $duration ${extra[*]:-}"
limit=$(python3 -c "print(int(float('$duration') + float('$messages') * 0.05 + 120))")
set +e
timeout "$limit" scripts/netns.sh bash -c '
    . "$ENV_SH"
    "$BIN" serve --params launch_params/spring5.yaml --model "$MODEL" \
        --set horizon="$HORIZON" --set diagnostics_period=0.5 2>"$LOG" &
    node=$!
    for _ in $(seq 200); do grep -q serving "$LOG" && break; sleep 0.05; done
    python3 scripts/ros/bench_node.py --node-pid $node $BENCH_ARGS
    rc=$?
    kill -INT $node
    for _ in $(seq 50); do kill -0 $node 2>/dev/null || break; sleep 0.1; done
    kill -0 $node 2>/dev/null && { echo "node ignored SIGINT" >&2; kill -KILL $node; }
    wait $node
    exit $rc
' | tee "$work/bench.out"
rc=${PIPESTATUS[0]}
set -e
if [ "$rc" -ne 0 ]; then
    echo "ros_bench.sh: the bench failed (exit $rc); node log:" >&2
    tail -20 "$work/node.log" >&2
    exit 1
fi
if grep -q panicked "$work/node.log"; then
    echo "ros_bench.sh: the node panicked:" >&2
    cat "$work/node.log" >&2
    exit 1
fi
echo "machine: $(nproc) cores, $(uname -sr)"
if [ -n "$out" ]; then
    sed -n 's/^BENCH_JSON //p' "$work/bench.out" >"$out"
    echo "report: $out"
fi
