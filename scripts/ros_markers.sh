#!/usr/bin/env bash
# Records what RViz and Foxglove would show of the node, and draws it: serves
# the shipped 5-pendulum MCGNODE model (launch_params/pendulum5.yaml) with
# recording on, plays states of bags/pendulum5-sample.mcap into it from rclpy
# (scripts/ros/play_bag.py), stops the node, and draws the last recorded
# visualization_msgs/MarkerArray with `mcgnode bag draw` (particles, bars,
# pivot, the 1 s predicted paths, force arrows). All DDS traffic stays in a
# private network namespace (scripts/netns.sh).
#
#     scripts/ros_markers.sh OUT.png [--states 20] [--keep DIR]
#
# --keep DIR keeps the recording (an MCAP that opens in Foxglove) in DIR.
# Needs the release binary (cargo build --release; $CARGO_TARGET_DIR is
# honoured, BIN=path overrides) and the rclpy venv (scripts/setup_venv.sh).
set -euo pipefail
ROOT="$(cd "$(dirname "$0")/.." && pwd)"
cd "$ROOT"
[ $# -ge 1 ] && [ "$1" != "-h" ] && [ "$1" != "--help" ] || { sed -n '2,14p' "$0" | sed 's/^# \{0,1\}//'; exit 0; }
png="$(realpath -m "$1")"; shift
states=20 keep=""
while [ $# -gt 0 ]; do
    case "$1" in
    --states) states="$2"; shift 2 ;;
    --keep) keep="$(realpath -m "$2")"; shift 2 ;;
    *) echo "ros_markers.sh: unknown option $1 (see --help)" >&2; exit 2 ;;
    esac
done
BIN="${BIN:-${CARGO_TARGET_DIR:-$ROOT/target}/release/mcgnode}"
[ -x "$BIN" ] || { echo "error: $BIN missing; run: cargo build --release" >&2; exit 1; }
scripts/build_msgs.sh >/dev/null
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
rec="${keep:-$work/rec}"
mkdir -p "$rec"

export BIN REC="$rec" STATES="$states" LOG="$work/node.log" ENV_SH="$ROOT/build/msgs/env.sh"
timeout 120 scripts/netns.sh bash -c '
    . "$ENV_SH"
    "$BIN" serve --params launch_params/pendulum5.yaml --set record_dir="$REC" \
        --set markers_period=0 2>"$LOG" &
    node=$!
    for _ in $(seq 200); do grep -q serving "$LOG" && break; sleep 0.05; done
    python3 scripts/ros/play_bag.py bags/pendulum5-sample.mcap --rate 20 --limit "$STATES"
    rc=$?
    sleep 0.5
    kill -INT $node
    for _ in $(seq 50); do kill -0 $node 2>/dev/null || break; sleep 0.1; done
    kill -0 $node 2>/dev/null && { echo "node ignored SIGINT" >&2; kill -KILL $node; }
    wait $node
    exit $rc
' || { echo "ros_markers.sh: the run failed; node log:" >&2; tail -20 "$work/node.log" >&2; exit 1; }
bag="$(ls "$rec"/*.mcap | tail -1)"
"$BIN" bag draw "$bag" --png "$png"
