#!/usr/bin/env bash
# The whole test suite, from a fresh clone: provisions the Python venv (rclpy and
# independent MCAP readers from PyPI), builds the ROS 2 interface package from
# msg/, then runs every Rust test (unit, integration, ROS 2 against real rclpy)
# in release mode. Extra arguments go to `cargo test`. Prints the time each step
# and each test binary (one per tests/*.rs file) took, and fails if the suite left
# a `mcgnode serve` running.
set -euo pipefail
cd "$(dirname "$0")/.."
before=$(pgrep -f 'mcgnode serve' | sort || true)
step() { local t0=$SECONDS; "$@"; echo "== time: $(( SECONDS - t0 )) s for: $*"; }
echo "== provisioning .venv (rclpy, mcap readers)"
step scripts/setup_venv.sh
echo "== building the mcgnode_msgs interface package"
step scripts/build_msgs.sh >/dev/null
echo "== cargo test --release"
# Timestamp cargo's output: each "Running <file>" / "Doc-tests" line starts a
# test binary; the time until the next one is that file's time.
timings=$(mktemp)
t0=$SECONDS
set +e
cargo test --release "$@" 2>&1 | {
    cur="" start=$SECONDS
    while IFS= read -r line; do
        printf '%s\n' "$line"
        case "$line" in
        "     Running "* | "   Doc-tests "*)
            [ -n "$cur" ] && echo "$cur: $(( SECONDS - start )) s" >>"$timings"
            cur=$(sed -E 's/^ *(Running|Doc-tests) +//; s/ \(.*//' <<<"$line")
            start=$SECONDS ;;
        esac
    done
    [ -n "$cur" ] && echo "$cur: $(( SECONDS - start )) s" >>"$timings"
}
status=${PIPESTATUS[0]}
set -e
echo "== time per test file (cargo test --release, $(( SECONDS - t0 )) s in all, build included)"
cat "$timings"
rm -f "$timings"
after=$(pgrep -f 'mcgnode serve' | sort || true)
left=$(comm -13 <(printf '%s\n' "$before") <(printf '%s\n' "$after") | grep . || true)
if [ -n "$left" ]; then
    echo "test.sh: the suite left 'mcgnode serve' running: $left" >&2
    ps -o pid,args -p "$(tr '\n' , <<<"$left" | sed 's/,$//')" >&2 || true
    exit 1
fi
exit "$status"
