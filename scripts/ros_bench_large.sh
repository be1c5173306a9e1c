#!/usr/bin/env bash
# Large predictions against a default rclpy subscriber (a bench, not a test).
# Runs `mcgnode serve` (truth:spring, or --model FILE; horizon 100) and scripts/ros/bench_large.py
# together in a private network namespace (scripts/netns.sh): --messages states
# of --particles particles, each followed by 5-particle states, publish ->
# receipt p50/p99/max of the PredictedTrajectory (taken raw), optionally
# Rollout calls (--rollout).
#
#     scripts/ros_bench_large.sh [--particles 1000] [--messages 20] [--small 5]
#                                [--rollout] [--timeout 20] [--bin PATH]
#                                [--model FILE --contacts]
#
# --contacts publishes triangular packings touching within radius 1 (six
# contacts each inside); serve a model trained with --radius 1 (--model FILE).
#
# Needs the release binary (cargo build --release; $CARGO_TARGET_DIR is
# honoured) and the rclpy venv (scripts/setup_venv.sh). NODE_LOG=FILE keeps
# the node's log (stderr) there instead of a temporary file.
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
cd "$ROOT"
BIN="${CARGO_TARGET_DIR:-$ROOT/target}/release/mcgnode"
MODEL=truth:spring
args=()
while [ $# -gt 0 ]; do
    case "$1" in
    --bin) BIN="$2"; shift 2 ;;
    --model) MODEL="$(cd "$(dirname "$2")" && pwd)/$(basename "$2")"; shift 2 ;;
    --contacts) args+=("$1"); shift ;;
    --particles | --messages | --small | --timeout | --steps) args+=("$1" "$2"); shift 2 ;;
    --rollout) args+=("$1"); shift ;;
    -h | --help) sed -n '2,18p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "ros_bench_large.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
    esac
done
[ -x "$BIN" ] || { echo "error: $BIN missing; run: cargo build --release" >&2; exit 1; }
scripts/build_msgs.sh >/dev/null
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
export BIN MODEL LOG="${NODE_LOG:-$work/node.log}" ENV_SH="$ROOT/build/msgs/env.sh" BENCH_ARGS="${args[*]:-}"
set +e
timeout 900 scripts/netns.sh bash -c '
    . "$ENV_SH"
    "$BIN" serve --model "$MODEL" --set horizon=100 --set dt=0.001 2>"$LOG" &
    node=$!
    for _ in $(seq 200); do grep -q serving "$LOG" && break; sleep 0.05; done
    python3 scripts/ros/bench_large.py $BENCH_ARGS
    rc=$?
    kill -INT $node
    for _ in $(seq 50); do kill -0 $node 2>/dev/null || break; sleep 0.1; done
    kill -0 $node 2>/dev/null && { echo "node ignored SIGINT" >&2; kill -KILL $node; }
    wait $node
    exit $rc
'
rc=$?
set -e
if [ "$rc" -ne 0 ]; then
    echo "ros_bench_large.sh: the bench failed (exit $rc); node log:" >&2
    tail -20 "$LOG" >&2
    exit 1
fi
echo "machine: $(nproc) cores, load $(cut -d' ' -f1-3 /proc/loadavg)"
