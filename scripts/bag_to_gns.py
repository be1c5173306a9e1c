#!/usr/bin/env python3
"""Write an mcgnode bag as a GNS-format dataset (Sanchez-Gonzalez et al. 2020).

Usage: bag_to_gns.py BAG OUTDIR [--split train] [--no-dt]

Writes OUTDIR/{split}.tfrecord (one tf.train.SequenceExample per trajectory,
written by the `tfrecord` package, no TensorFlow: context `key` int64 and
`particle_type` bytes of int64, feature list `position` bytes of float32 per
step, shape (steps, particles, dim)) and OUTDIR/metadata.json (dim, dt,
sequence_length, default_connectivity_radius, bounds, vel/acc mean and std
per step, as GNS computes them). Kinematic particles get GNS's boundary type
3, the others GNS's water type 5. The bag is decoded by `mcap` and
`mcap-ros2-support`, independently of mcgnode. --no-dt leaves `dt` out of the
metadata (as some converted datasets do). Run with the project's venv:
.venv/bin/python3 (scripts/setup_venv.sh installs the packages).
"""

import argparse
import json
from pathlib import Path

import numpy as np
from _particle_bag import TYPE, read_bag
from tfrecord.writer import TFRecordWriter


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bag", type=Path)
    ap.add_argument("outdir", type=Path)
    ap.add_argument("--split", default="train")
    ap.add_argument("--no-dt", action="store_true")
    args = ap.parse_args()
    trajs = read_bag(args.bag)
    if not trajs:
        raise SystemExit(f"{args.bag}: no {TYPE} messages")
    args.outdir.mkdir(parents=True, exist_ok=True)
    writer = TFRecordWriter(str(args.outdir / f"{args.split}.tfrecord"))
    first = next(iter(trajs.values()))
    dim, radius = first[0].dimension, first[0].interaction_radius
    stamps = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in first]
    dt = round(stamps[1] - stamps[0], 9)
    vels, accs, lo, hi, steps = [], [], None, None, 0
    for key, msgs in sorted(trajs.items()):
        msgs.sort(key=lambda m: m.step)
        pos = np.array(
            [[[p.x, p.y, p.z][:dim] for p in m.positions] for m in msgs], dtype=np.float32
        )
        kin = list(msgs[0].kinematic) or [False] * pos.shape[1]
        types = np.array([3 if k else 5 for k in kin], dtype=np.int64)
        writer.write(
            {"key": (key, "int"), "particle_type": (types.tobytes(), "byte")},
            {"position": ([step.tobytes() for step in pos], "byte")},
        )
        p = pos.astype(np.float64)
        v = p[1:] - p[:-1]
        vels.append(v.reshape(-1, dim))
        accs.append((v[1:] - v[:-1]).reshape(-1, dim))
        flat = p.reshape(-1, dim)
        lo = flat.min(0) if lo is None else np.minimum(lo, flat.min(0))
        hi = flat.max(0) if hi is None else np.maximum(hi, flat.max(0))
        steps = pos.shape[0]
    writer.close()
    v, a = np.concatenate(vels), np.concatenate(accs)
    meta = {
        "bounds": [[float(x), float(y)] for x, y in zip(lo, hi)],
        "sequence_length": steps - 1,
        "default_connectivity_radius": radius,
        "dim": dim,
        "vel_mean": v.mean(0).tolist(),
        "vel_std": v.std(0).tolist(),
        "acc_mean": a.mean(0).tolist(),
        "acc_std": a.std(0).tolist(),
    }
    if not args.no_dt:
        meta["dt"] = dt
    (args.outdir / "metadata.json").write_text(json.dumps(meta, indent=1))
    print(f"wrote {args.outdir}: {len(trajs)} trajectories of {steps} steps, dim {dim}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
