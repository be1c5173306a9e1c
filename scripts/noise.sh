#!/usr/bin/env bash
# How predictions from position-only streams degrade with tracker noise: the
# README's table. For the shipped 5-spring and 5-pendulum MCGNODE models:
# ground truth at 100 Hz (unseen seed), observed by `mcgnode bag observe` as
# positions only with Gaussian noise of 0, 0.1 % and 1 % of the particle
# spacing, replayed the way the node predicts from such a stream (velocities
# estimated causally: without a smoother, with the poly smoother, and with the
# model smoother, fitted through the model's own rollout) and scored against
# the noise-free truth (`replay --reference`). RE at lead 0.1 s and 1 s,
# beside standing still's (predicting that nothing moves) on the same starts.
#
#   scripts/noise.sh [OUT_DIR]      # bags in OUT_DIR (default: a temporary folder)
#
# Environment: MCGNODE (the binary; default target/release/mcgnode, built if
# missing), TRAJECTORIES (default 4), STATES (per trajectory, default 301),
# WINDOWS (the poly and model smoothers'
# windows tried, default "9 25").
set -euo pipefail
cd "$(dirname "$0")/.."
BIN=${MCGNODE:-target/release/mcgnode}
[ -x "$BIN" ] || cargo build --release --quiet
BIN=$(realpath "$BIN")
OUT=${1:-$(mktemp -d)}
mkdir -p "$OUT"
TRAJ=${TRAJECTORIES:-4}
STATES=${STATES:-301}
WINDOWS=${WINDOWS:-9 25}

# Mean RE at leads 0.1 s and 1 s of one replay (JSON on stdin), then the
# standing-still reference's on the same starts.
at_leads() {
    python3 -c '
import json, sys
r = json.load(sys.stdin)
t, g = r["summary"]["t"], r["summary"]["re"]["gmean"]
at = lambda x: g[min(range(len(t)), key=lambda i: abs(t[i] - x))]
still = r["still"]["re"]
st = lambda x: still[min(range(len(t)), key=lambda i: abs(t[i] - x))]
print("%.2e | %.2e | %.2e | %.2e" % (at(0.1), at(1.0), st(0.1), st(1.0)))'
}

echo "| system | input | smoother | RE at 0.1 s | RE at 1 s | still at 0.1 s | still at 1 s |"
echo "| --- | --- | --- | --- | --- | --- | --- |"
for system in spring pendulum; do
    model=bags/models/${system}5-mcgnode.json
    # 100 Hz: the pendulum's simulator saves every 1000 of its 1e-5 s steps.
    if [ "$system" = spring ]; then every=10; dt=0.001; else every=1000; dt=0.0001; fi
    truth="$OUT/$system-truth.mcap"
    "$BIN" simulate --system "$system" --save-every "$every" --states "$STATES" \
        --trajectories "$TRAJ" --seed 7 --out "$truth" >/dev/null 2>&1
    replay() {
        "$BIN" replay --bag "$1" --model "$model" --horizon 1.0 --stride 10 --dt "$dt" \
            --json "${@:2}" 2>/dev/null | at_leads
    }
    echo "| $system | full states | - | $(replay "$truth") |"
    for noise in 0 0.001 0.01; do
        bag="$OUT/$system-noise-$noise.mcap"
        "$BIN" bag observe "$truth" --out "$bag" --noise "$noise" --seed 3 >/dev/null
        label="positions, noise $(python3 -c "print('%g %%' % ($noise * 100))")"
        echo "| $system | $label | none | $(replay "$bag" --reference "$truth") |"
        for w in $WINDOWS; do
            echo "| $system | $label | poly $w | $(replay "$bag" --reference "$truth" \
                --smoother poly --smoother-window "$w") |"
            echo "| $system | $label | model $w | $(replay "$bag" --reference "$truth" \
                --smoother model --smoother-window "$w") |"
        done
    done
done
