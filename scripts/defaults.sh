#!/usr/bin/env bash
# The README's "Defaults that learn" table from a clean clone: for each system
# (the 125-particle cube, a 27-particle peridynamic lattice, a 27-particle
# harmonic lattice from scripts/sim_lattice3d.py written by rosbags, 5 springs,
# 5 pendulums) simulate training and held-out trajectories, train MCGNODE with
# nothing but `--out` (the default recipe) and, for comparison, with the paper's
# settings at 300 epochs, and evaluate both beside the standing-still
# reference. Wall, user and system times go to OUT/times.txt; the table to
# OUT/table.md.
# Usage: scripts/defaults.sh OUT [SYSTEM ...] (systems: cube p27 py s5 p5;
# default all). MCGNODE=path/to/mcgnode uses that binary; PAPER=0 skips the
# paper-setting runs.
set -euo pipefail
OUT="${1:?usage: scripts/defaults.sh OUT [SYSTEM ...]}"
shift
SYSTEMS=("${@:-cube p27 py s5 p5}")
read -r -a SYSTEMS <<< "${SYSTEMS[*]}"
cd "$(dirname "$0")/.."
ROOT=$PWD
if [ -z "${MCGNODE:-}" ]; then
    cargo build --release -q
fi
M="${MCGNODE:-${CARGO_TARGET_DIR:-$PWD/target}/release/mcgnode}"
PY="$ROOT/.venv/bin/python3"
mkdir -p "$OUT" && cd "$OUT"
data() {
    case "$1" in
        cube) "$M" simulate --system peridynamic --trajectories 10 --seed 1 --out cube-train.mcap
              "$M" simulate --system peridynamic --trajectories 4 --seed 2 --out cube-test.mcap ;;
        p27) "$M" simulate --system peridynamic --particles 27 --trajectories 30 --seed 1 --out p27-train.mcap
             "$M" simulate --system peridynamic --particles 27 --trajectories 4 --seed 2 --out p27-test.mcap ;;
        py) [ -x "$PY" ] || { echo "run scripts/setup_venv.sh first (needs rosbags, numpy)" >&2; exit 1; }
            rm -rf py-train py-test
            "$PY" "$ROOT/scripts/sim_lattice3d.py" py-train --trajectories 30 --seed 0
            "$PY" "$ROOT/scripts/sim_lattice3d.py" py-test --trajectories 4 --seed 7 ;;
        s5) "$M" simulate --system spring --particles 5 --trajectories 100 --seed 1 --out s5-train.mcap
            "$M" simulate --system spring --particles 5 --trajectories 20 --seed 2 --states 201 --out s5-test.mcap ;;
        p5) "$M" simulate --system pendulum --particles 5 --trajectories 100 --seed 1 --out p5-train.mcap
            "$M" simulate --system pendulum --particles 5 --trajectories 20 --seed 2 --out p5-test.mcap ;;
        *) echo "unknown system $1 (cube p27 py s5 p5)" >&2; exit 1 ;;
    esac
}
# The bag of SYSTEM's PART (train, test): a rosbag2 directory for the Python lattice.
bag() { if [ "$1" = py ]; then echo "py-$2"; else echo "$1-$2.mcap"; fi; }
run() { # NAME SYSTEM [train flags]
    local name=$1 sys=$2
    shift 2
    /usr/bin/time -f "$name: %e s wall, %U s user, %S s system (load before: $(cut -d' ' -f1-3 /proc/loadavg))" \
        -a -o times.txt "$M" train --model mcgnode --data "$(bag "$sys" train)" --out "$name.json" --quiet "$@"
    "$M" evaluate --model "$name.json" --bag "$(bag "$sys" test)" --json > "$name.eval.json"
}
for sys in "${SYSTEMS[@]}"; do
    data "$sys"
    run "$sys-default" "$sys"
    if [ "${PAPER:-1}" != 0 ]; then
        run "$sys-paper" "$sys" --recipe paper --epochs 300
    fi
done
python3 - "${SYSTEMS[@]}" <<'EOF' | tee table.md
import json, os, sys
print("| run | epochs, batch | explained | RE at 1 s (still) | x | RE time-average (still) | x |")
print("| --- | --- | --- | --- | --- | --- | --- |")
for sys_ in sys.argv[1:]:
    for kind in ("default", "paper"):
        name = f"{sys_}-{kind}"
        if not os.path.exists(name + ".eval.json"):
            continue
        e = json.load(open(name + ".eval.json"))
        t = json.load(open(name + ".json"))["training"]
        ts, re, st = e["summary"]["t"], e["summary"]["re"]["gmean"], e["still"]
        i = min(range(len(ts)), key=lambda k: abs(ts[k] - 1.0))
        print(f"| {name} | {t['epochs_run']}, {t['batch']} | {100 * t['explained']:.2f} % "
              f"| {re[i]:.2e} ({st['re'][i]:.2e}) | {st['re'][i] / re[i]:.1f} "
              f"| {e['averages']['re']:.2e} ({st['re_mean']:.2e}) | {st['times_better']:.1f} |")
EOF
cat times.txt
