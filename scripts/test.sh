#!/usr/bin/env bash
# The whole test suite, from a fresh clone: provisions the Python venv (rclpy and
# independent MCAP readers from PyPI), builds the ROS 2 interface package from
# msg/, then runs every Rust test (unit, integration, ROS 2 against real rclpy,
# doc tests) in release mode. Extra arguments go to `cargo test` (e.g.
# `--test ros_node`, or `-- name_filter` for the test binaries).
#
# To fit CI's time on 2 cores: the venv and msg/ are provisioned while cargo
# compiles, the test binaries are built once (`cargo test --no-run`) and then run
# two at a time (TEST_JOBS, default 2), longest first; each binary's output is
# printed whole when it ends, with its time. Every test binary runs with cargo's
# working directory (its package's root). Fails if any binary fails, and if the
# suite left a `mcgnode serve` running.
set -euo pipefail
cd "$(dirname "$0")/.."
root=$PWD
before=$(pgrep -f 'mcgnode serve' | sort || true)
step() { local t0=$SECONDS; "$@"; echo "== time: $(( SECONDS - t0 )) s for: $*"; }
jobs=${TEST_JOBS:-2}
if ! [[ $jobs =~ ^[1-9][0-9]*$ ]]; then
    echo "test.sh: TEST_JOBS=$jobs is not a positive count of test binaries to run at once (e.g. TEST_JOBS=2)" >&2
    exit 2
fi
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT

# Cargo options before `--` build and select; what follows `--` goes to each binary.
cargo_args=() bin_args=()
while [ $# -gt 0 ]; do
    if [ "$1" = "--" ]; then shift; bin_args=("$@"); break; fi
    cargo_args+=("$1"); shift
done

echo "== provisioning .venv (rclpy, mcap readers) and msg/, beside the build"
( step scripts/setup_venv.sh && step scripts/build_msgs.sh >/dev/null ) >"$work/provision.log" 2>&1 &
provision=$!

echo "== cargo test --release --no-run"
t0=$SECONDS
if ! cargo test --release --no-run --message-format=json-render-diagnostics \
    "${cargo_args[@]}" >"$work/artifacts.json"; then
    wait "$provision" || true
    exit 1
fi
echo "== time: $(( SECONDS - t0 )) s for: building the test binaries"
if ! wait "$provision"; then
    cat "$work/provision.log"
    echo "test.sh: provisioning failed (above)" >&2
    exit 1
fi
cat "$work/provision.log"

# One line per test binary: its name as cargo prints it, its package root, its path.
python3 - "$work/artifacts.json" >"$work/binaries" <<'EOF'
import json, os, sys
for line in open(sys.argv[1]):
    m = json.loads(line)
    if m.get("reason") != "compiler-artifact" or not m.get("executable"):
        continue
    if not m["profile"]["test"]:
        continue
    t = m["target"]
    root = os.path.dirname(m["manifest_path"])
    src = os.path.relpath(t["src_path"], root)
    name = f"unittests {src}" if "lib" in t["kind"] or "bin" in t["kind"] else src
    if root != os.getcwd():
        name = f"{os.path.relpath(root)}: {name}"
    print(f"{name}\t{root}\t{m['executable']}")
EOF
# Doc tests too, when nothing narrower was asked for.
if [ ${#cargo_args[@]} -eq 0 ]; then
    printf 'doc tests\t%s\tcargo test --release --doc\n' "$root" >>"$work/binaries"
fi

# Longest first (the order of the last measured run on 2 cores; others after).
order="tests/colcon.rs tests/ros_stream.rs tests/ros_accuracy.rs tests/ros_node.rs tests/python.rs
tests/reproduce.rs tests/readme.rs tests/noise.rs tests/rosbag2.rs tests/ros_train.rs
tests/contact_models.rs tests/fuzz_readers.rs tests/plan.rs tests/ros_large.rs"
rank() { local i=0 f; for f in $order; do [ "$f" = "$1" ] && { echo $i; return; }; i=$((i + 1)); done; echo 99; }
while IFS=$'\t' read -r name dir exe; do
    printf '%s\t%s\t%s\t%s\n' "$(rank "$name")" "$name" "$dir" "$exe"
done <"$work/binaries" | sort -s -n -k1,1 | cut -f2- >"$work/queue"

run_one() { # name dir exe: prints its output and appends its time; a failure to $work/failed
    local name=$1 dir=$2 exe=$3 out t0 rc
    out=$(mktemp -p "$work")
    t0=$SECONDS
    set +e
    # The environment cargo gives a test binary: its package root as working
    # directory and CARGO_MANIFEST_DIR, the target's libraries on the path.
    (
        cd "$dir"
        export CARGO_MANIFEST_DIR=$dir
        export LD_LIBRARY_PATH="$root/target/release/deps:$root/target/release${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"
        read -r -a cmd <<<"$exe"
        exec "${cmd[@]}" "${bin_args[@]}"
    ) >"$out" 2>&1
    rc=$?
    set -e
    {
        echo "     Running $name"
        cat "$out"
        echo "$name: $(( SECONDS - t0 )) s$([ $rc -ne 0 ] && echo " FAILED (exit $rc)")" >>"$work/timings"
    } | flock "$work/print.lock" cat
    [ $rc -eq 0 ] || echo "$name" >>"$work/failed"
    rm -f "$out"
}

echo "== running $(wc -l <"$work/queue") test binaries, $jobs at a time"
t0=$SECONDS
: >"$work/timings"
exec 8<"$work/queue"
worker() {
    local line
    # One line at a time from the shared queue, under a lock so no two take it.
    while line=$(flock "$work/queue.lock" bash -c 'IFS= read -r l <&8 && printf "%s" "$l"'); do
        IFS=$'\t' read -r name dir exe <<<"$line"
        run_one "$name" "$dir" "$exe"
    done
}
pids=()
for _ in $(seq "$jobs"); do worker & pids+=($!); done
for p in "${pids[@]}"; do wait "$p"; done
echo "== time per test binary ($jobs at a time, $(( SECONDS - t0 )) s in all)"
cat "$work/timings"

status=0
if [ -s "$work/failed" ]; then
    echo "test.sh: failed: $(paste -sd, "$work/failed")" >&2
    status=1
fi
after=$(pgrep -f 'mcgnode serve' | sort || true)
left=$(comm -13 <(printf '%s\n' "$before") <(printf '%s\n' "$after") | grep . || true)
if [ -n "$left" ]; then
    echo "test.sh: the suite left 'mcgnode serve' running: $left" >&2
    ps -o pid,args -p "$(tr '\n' , <<<"$left" | sed 's/,$//')" >&2 || true
    exit 1
fi
exit "$status"
