#!/usr/bin/env bash
# Proves scripts/netns.sh leaves nothing running: a command that starts a
# background child and then fails, and one whose netns.sh is SIGKILLed midway (as
# when a Rust test panics and its Child is killed), must both leave no process.
set -euo pipefail
cd "$(dirname "$0")/.."
marker="netns-orphan-probe-$$"
alive() { pgrep -f "$marker" >/dev/null; }
# 1. the command exits (with failure) leaving a background child behind.
rc=0
scripts/netns.sh bash -c "(exec -a $marker sleep 600) & sleep 0.3; exit 7" 2>/dev/null || rc=$?
[ "$rc" = 7 ] || { echo "netns cleanup: exit status $rc, want 7" >&2; exit 1; }
sleep 0.3
if alive; then echo "netns cleanup: orphan survived its command's exit" >&2; pkill -f "$marker"; exit 1; fi
# 2. netns.sh itself is killed while its command still runs.
scripts/netns.sh bash -c "(exec -a $marker sleep 600) & sleep 600" 2>/dev/null &
outer=$!
for _ in $(seq 50); do alive && break; sleep 0.1; done
alive || { echo "netns cleanup: probe never started" >&2; kill -9 "$outer"; exit 1; }
kill -9 "$outer"; wait "$outer" 2>/dev/null || true
for _ in $(seq 50); do alive || break; sleep 0.1; done
if alive; then echo "netns cleanup: orphan survived SIGKILL of netns.sh" >&2; pkill -f "$marker"; exit 1; fi
echo "netns cleanup: ok (no process survives exit or SIGKILL)"
