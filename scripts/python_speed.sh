#!/usr/bin/env bash
# The README's "From Python" speed figure: one rollout of a 5,000-spring ring
# (the shipped 5-spring MCGNODE, 2,000 steps of 1e-3 s, every 100th state
# kept) through the CLI (`mcgnode rollout --initial`) and through Python
# (`mcgnode.read_bag` + `Model.rollout`), each a whole process (start,
# reading the bag, loading the model, the rollout; the CLI also writes its
# bag), REPEATS times alternately; prints wall, user and sys seconds per run
# and the rollout alone as each reports it.
# Needs the release binary and the package installed in .venv
# (tests/python.rs does both; or `pip install ./python`).
# Usage: scripts/python_speed.sh [REPEATS] (default 3).
set -euo pipefail
cd "$(dirname "$0")/.."
REPEATS=${1:-3}
BIN=${MCGNODE_BIN:-${CARGO_TARGET_DIR:-target}/release/mcgnode}
PY=.venv/bin/python3
MODEL=bags/models/spring5-mcgnode.json
DIR=$(mktemp -d)
trap 'rm -rf "$DIR"' EXIT
"$BIN" simulate --particles 5000 --trajectories 1 --states 2 --seed 11 --out "$DIR/ring.mcap" >/dev/null
cat >"$DIR/roll.py" <<'PY'
import sys, time
import mcgnode
tr = mcgnode.read_bag(sys.argv[1])[0]
m = mcgnode.load_model(sys.argv[2])
t0 = time.perf_counter()
out = m.rollout(tr, 2000, every=100)
print(f"rollout {time.perf_counter() - t0:.3f} s", file=sys.stderr)
PY
for i in $(seq "$REPEATS"); do
    /usr/bin/time -f "cli    wall %e s  user %U s  sys %S s" \
        "$BIN" rollout --model "$MODEL" --initial "$DIR/ring.mcap" --duration 2 \
        --save-every 100 --out "$DIR/cli.mcap" 2>&1 | sed 's/^/  /'
    /usr/bin/time -f "python wall %e s  user %U s  sys %S s" \
        "$PY" "$DIR/roll.py" "$DIR/ring.mcap" "$MODEL" 2>&1 | sed 's/^/  /'
done
