#!/usr/bin/env python3
"""Write an mcgnode bag as a LagrangeBench-format dataset (Toshev et al. 2023).

Usage: bag_to_lagrangebench.py BAG OUTDIR [--split train] [--float32] [--drop KEY]

Writes OUTDIR/{split}.h5 (written by h5py: one group per trajectory, named
00000, 00001, ..., holding `position` (steps, particles, dim), float64 or
with --float32 float32, and `particle_type` (particles,) int32) and
OUTDIR/metadata.json (dim, dt, write_every 1, bounds,
periodic_boundary_conditions, default_connectivity_radius, and the
velocity/acceleration statistics as LagrangeBench lists them). Kinematic
particles get LagrangeBench's solid-wall type 1, the others fluid 0. A bag
with a periodic box gives its bounds and flags; otherwise the bounds are the
positions' extent and no axis is periodic. The bag is decoded by `mcap` and
`mcap-ros2-support`, independently of mcgnode. --drop KEY leaves a metadata
key out (to test the importer's refusal). Run with the project's venv:
.venv/bin/python3 (scripts/setup_venv.sh installs h5py).
"""

import argparse
import json
from pathlib import Path

import h5py
import numpy as np
from _particle_bag import TYPE, read_bag


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bag", type=Path)
    ap.add_argument("outdir", type=Path)
    ap.add_argument("--split", default="train")
    ap.add_argument("--float32", action="store_true")
    ap.add_argument("--drop", action="append", default=[])
    args = ap.parse_args()
    trajs = read_bag(args.bag)
    if not trajs:
        raise SystemExit(f"{args.bag}: no {TYPE} messages")
    args.outdir.mkdir(parents=True, exist_ok=True)
    first = next(iter(trajs.values()))
    m0 = first[0]
    dim, radius = m0.dimension, m0.interaction_radius
    stamps = [m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in first]
    dt = round(stamps[1] - stamps[0], 9)
    periodic = list(getattr(m0, "box_periodic", []))[:dim]
    dtype = np.float32 if args.float32 else np.float64
    vels, accs, lo, hi = [], [], None, None
    with h5py.File(args.outdir / f"{args.split}.h5", "w") as f:
        for k, (_, msgs) in enumerate(sorted(trajs.items())):
            msgs.sort(key=lambda m: m.step)
            pos = np.array([[[p.x, p.y, p.z][:dim] for p in m.positions] for m in msgs], dtype=dtype)
            kin = list(msgs[0].kinematic) or [False] * pos.shape[1]
            g = f.create_group(f"{k:05d}")
            g.create_dataset("position", data=pos)
            g.create_dataset("particle_type", data=np.array([1 if x else 0 for x in kin], dtype=np.int32))
            p = pos.astype(np.float64)
            v = p[1:] - p[:-1]
            vels.append(v.reshape(-1, dim))
            accs.append((v[1:] - v[:-1]).reshape(-1, dim))
            flat = p.reshape(-1, dim)
            lo = flat.min(0) if lo is None else np.minimum(lo, flat.min(0))
            hi = flat.max(0) if hi is None else np.maximum(hi, flat.max(0))
    if periodic and any(periodic):
        lo_box, hi_box = (m0.box_lower.x, m0.box_lower.y, m0.box_lower.z), (m0.box_upper.x, m0.box_upper.y, m0.box_upper.z)
        bounds = [[float(lo_box[i]), float(hi_box[i])] for i in range(dim)]
    else:
        bounds = [[float(x), float(y) + 1e-9] for x, y in zip(lo, hi)]
        periodic = [False] * dim
    v, a = np.concatenate(vels), np.concatenate(accs)
    meta = {
        "case": "from an mcgnode bag",
        "dim": dim,
        "dt": dt,
        "write_every": 1,
        "bounds": bounds,
        "periodic_boundary_conditions": [bool(x) for x in periodic] + [all(periodic)] * (3 - dim),
        "default_connectivity_radius": radius,
        "num_particles_max": int(max(len(ms[0].positions) for ms in trajs.values())),
        "vel_mean": v.mean(0).tolist(),
        "vel_std": v.std(0).tolist(),
        "acc_mean": a.mean(0).tolist(),
        "acc_std": a.std(0).tolist(),
    }
    for key in args.drop:
        meta.pop(key, None)
    (args.outdir / "metadata.json").write_text(json.dumps(meta, indent=1))
    print(f"wrote {args.outdir}: {len(trajs)} trajectories, dim {dim}, periodic {periodic}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
