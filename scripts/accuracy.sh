#!/usr/bin/env bash
# Reproduces the accuracy figures in the README: full training (paper protocol,
# 10,000 epochs max with early stopping) of 5-spring MCGNODE and 5-pendulum
# CGNODE/MCGNODE, evaluated on 100 held-out trajectories (seed 2; training uses seed 1).
# The paper's settings (--recipe paper: batch 100, lr 1e-3, width 5) behind the
# README's table; RECIPE=auto trains with `train`'s default recipe instead.
# Usage: scripts/accuracy.sh [OUT_DIR] [EPOCHS]
set -euo pipefail
out=${1:-accuracy-out}
epochs=${2:-10000}
bin=${MCGNODE:-target/release/mcgnode}
recipe=${RECIPE:-paper}
[ -x "$bin" ] || cargo build --release
mkdir -p "$out"
run() { echo "+ $*" >&2; "$@"; }
run "$bin" simulate --system spring --particles 5 --trajectories 100 --seed 1 --out "$out/spring5-train.mcap"
run "$bin" simulate --system spring --particles 5 --trajectories 100 --seed 2 --states 201 --out "$out/spring5-test.mcap"
run "$bin" simulate --system pendulum --particles 5 --trajectories 100 --seed 1 --out "$out/pendulum5-train.mcap"
run "$bin" simulate --system pendulum --particles 5 --trajectories 100 --seed 2 --out "$out/pendulum5-test.mcap"
for job in "spring5 mcgnode" "pendulum5 cgnode" "pendulum5 mcgnode"; do
  set -- $job
  sys=$1 model=$2
  /usr/bin/time -f "%e s wall, %U s user, %S s system" -o "$out/$sys-$model.time" \
    "$bin" train --model "$model" --recipe "$recipe" --data "$out/$sys-train.mcap" --epochs "$epochs" --out "$out/$sys-$model.json" 2> "$out/$sys-$model.train.log"
  "$bin" evaluate --model "$out/$sys-$model.json" --bag "$out/$sys-test.mcap" --plot "$out/$sys-$model.png" > "$out/$sys-$model.eval.txt"
  "$bin" evaluate --model "$out/$sys-$model.json" --bag "$out/$sys-test.mcap" --json > "$out/$sys-$model.eval.json"
  cat "$out/$sys-$model.eval.txt"
done
