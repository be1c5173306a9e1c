#!/usr/bin/env bash
# Side-by-side speed: the authors' JAX code against `mcgnode bench`, in
# interleaved rounds on this machine (issue 24).
#
# Usage: scripts/bench_vs_reference.sh [--quick] [--rounds N] [--json OUT]
#                                      [--baselines REF2_DIR] REF_DIR
#   REF_DIR  a checkout of the authors' repository, made by you:
#            git clone https://github.com/M3RG-IITD/graph_neural_ODE REF_DIR
#   --quick  one round, one timed epoch / rollout each (checks the harness)
#   --rounds N   rounds (default 3; each: mcgnode, JAX 1 thread, JAX 2 threads)
#   --json OUT   also write every measurement as JSON
#   --baselines REF2_DIR  also time their LGN and HGN epochs from a checkout of
#            the same group's benchmark (made by you):
#            git clone https://github.com/M3RG-IITD/benchmarking_graph REF2_DIR
#
# Their code never enters this repository. The harness
#  - makes a venv REF_DIR/.venv-bench and installs their dependencies from PyPI
#    (pinned below; their requirements.txt pins jax 0.2.26 / jax-md 0.1.23,
#    which no longer install on current Python);
#  - copies the scripts it runs into REF_DIR/.mcgnode-bench/ and edits the
#    copies, printing each edit and why (scripts/bench_reference.py, EDITS),
#    with shims for jax API changes applied at import (SHIMS there);
#  - times their MCGNODE spring and pendulum scripts (not that repository's
#    LGN or HGN: its "LGN" script trains a graph network that outputs
#    accelerations, and its HGN scripts call functions its code does not
#    define; see NEEDED in scripts/bench_reference.py), and with --baselines
#    the full-graph LGN and HGN of their benchmark repository against
#    mcgnode's (candle) LGN and HGN epochs (BASELINE_EDITS there);
#  - generates their 5-spring and 5-pendulum data sets once with their data
#    scripts, then per round and per row: `mcgnode bench --json --only <figure>`,
#    their script with 1 thread, their script with 2 threads.
# Every timed process runs under `flock $BENCH_LOCK` (default /work/build.lock
# when it exists; set BENCH_LOCK= to disable) so builds do not overlap it.
# Uses target/release/mcgnode (or $CARGO_TARGET_DIR/release/mcgnode, or
# $MCGNODE_BIN), copied aside first so a rebuild cannot change it mid-run.
set -euo pipefail
ROOT=$(cd "$(dirname "$0")/.." && pwd)
usage() { sed -n '5,14p' "$0" | sed 's/^# \{0,1\}//' >&2; exit 2; }
QUICK=() ROUNDS=3 JSON=() REF= REF2=
while [ $# -gt 0 ]; do
    case "$1" in
        --quick) QUICK=(--quick); shift ;;
        --rounds) ROUNDS=${2:?}; shift 2 ;;
        --json) JSON=(--json "$(realpath -m "${2:?}")"); shift 2 ;;
        --baselines) REF2=${2:?}; shift 2 ;;
        -h|--help) usage ;;
        -*) echo "bench_vs_reference: unknown option $1" >&2; usage ;;
        *) [ -z "$REF" ] || usage; REF=$1; shift ;;
    esac
done
if [ -z "$REF" ]; then
    echo "bench_vs_reference: no REF_DIR given" >&2; usage
fi
# checkout DIR REPO FILE...: exits 2, naming the clone to make, unless DIR
# holds every scripts/FILE of a checkout of github.com/REPO.
checkout() {
    local dir=$1 repo=$2 f
    shift 2
    for f in "$@"; do
        if [ ! -e "$dir/scripts/$f" ]; then
            echo "bench_vs_reference: $dir is not a checkout of $repo" \
                "(no scripts/$f); make one with" >&2
            echo "  git clone https://github.com/$repo $dir" >&2
            exit 2
        fi
    done
}
checkout "$REF" M3RG-IITD/graph_neural_ODE psystems Spring-4MCGNODE.py
REF=$(cd "$REF" && pwd)
BASE_PREP=() BASE_RUN=()
if [ -n "$REF2" ]; then
    checkout "$REF2" M3RG-IITD/benchmarking_graph Spring-LGN.py Spring-HGN.py
    REF2=$(cd "$REF2" && pwd)
    mkdir -p "$REF2/.mcgnode-bench"
    BASE_PREP=(--baselines "$REF2" "$REF2/.mcgnode-bench")
    BASE_RUN=(--ref2 "$REF2" --work2 "$REF2/.mcgnode-bench")
fi

BIN_SRC=${MCGNODE_BIN:-${CARGO_TARGET_DIR:-$ROOT/target}/release/mcgnode}
if [ ! -x "$BIN_SRC" ]; then
    echo "bench_vs_reference: no release binary at $BIN_SRC;" \
        "build it: cargo build --release --bin mcgnode" >&2
    exit 2
fi
LOCK=${BENCH_LOCK-$( [ -e /work/build.lock ] && echo /work/build.lock || true )}
run_locked() { if [ -n "$LOCK" ]; then flock "$LOCK" "$@"; else "$@"; fi; }

# Versions that exist on PyPI and work together (checked 2026-12-02 on Python
# 3.11; their dependencies float, `pip freeze` goes to $VENV/freeze.txt).
PY=${BENCH_PYTHON:-python3}
PINS=("jax[cpu]==0.10.2" "jaxlib==0.10.2" "jax-md==0.2.29" "jraph==0.0.6.dev0"
      "dm-haiku==0.0.17" "fire==0.7.1" "frozendict==2.5.1" "scikit-learn==1.9.1"
      "matplotlib==3.11.2")
VENV=$REF/.venv-bench
WORK=$REF/.mcgnode-bench
mkdir -p "$WORK"
STAMP="$VENV/.mcgnode-pins"
if [ ! -x "$VENV/bin/python" ] || [ "$(cat "$STAMP" 2>/dev/null)" != "${PINS[*]}" ]; then
    echo "making $VENV with ${PINS[*]}"
    "$PY" -m venv "$VENV"
    run_locked timeout 1800 "$VENV/bin/pip" install -q "${PINS[@]}"
    "$VENV/bin/pip" freeze >"$VENV/freeze.txt"
    echo "${PINS[*]}" >"$STAMP"
fi
BIN=$WORK/mcgnode
cp "$BIN_SRC" "$BIN"

"$PY" "$ROOT/scripts/bench_reference.py" prepare "$REF" "$WORK" "${BASE_PREP[@]}"
LOAD=$(uptime)
COMMIT=$(git -C "$ROOT" rev-parse --short HEAD 2>/dev/null || echo "?")
echo "load at start: $LOAD"
exec "$PY" "$ROOT/scripts/bench_reference.py" harness --ref "$REF" --work "$WORK" \
    --mcgnode "$BIN" --venv-python "$VENV/bin/python" --lock "$LOCK" \
    --load-before "$LOAD" --commit-at-start "$COMMIT" --jaxmd 0.2.29 --rounds "$ROUNDS" "${QUICK[@]}" "${JSON[@]}" \
    "${BASE_RUN[@]}"
