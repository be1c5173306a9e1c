#!/usr/bin/env python3
"""A 3D harmonic lattice simulated in numpy and written by rosbags: data mcgnode did not make.

Usage: sim_lattice3d.py OUT [--side 3] [--trajectories 30] [--seed 0] [--states 100]
                        [--storage mcap|sqlite3]

Independent of mcgnode's code: its own lattice (simple cubic, spacing 0.8, bonds to
the 6 nearest and 12 face-diagonal neighbours, one stiffness 2.0 for every bond,
masses 1.5), its own initial states (every particle displaced by Gaussian noise of
4 % of the spacing and given Gaussian velocities, total momentum removed), its own
integrator (velocity Verlet, dt 1e-3, every 20th state saved, so 0.02 s between
states) and its own writer (rosbags' rosbag2 writer, types registered from
msg/ParticleState.msg). No `mcgnode` metadata record is written: the messages say
everything (field_status KNOWN with no gravity, drag or force: a closed system).
Accelerations are left empty, as a tool that records only the state writes them.
Energy and momentum are checked before writing (drift printed; refuses above 1e-6).
Run with the project's venv: .venv/bin/python3 (scripts/setup_venv.sh creates it).
"""

import argparse
import sys
from pathlib import Path

import numpy as np

SPACING = 0.8
STIFFNESS = 2.0
MASS = 1.5
DT = 1e-3
EVERY = 20


def lattice(side):
    """Positions (n, 3) and bonds [(a, b, rest)] of a side^3 simple cubic lattice."""
    idx = [(i, j, k) for i in range(side) for j in range(side) for k in range(side)]
    pos = np.array(idx, dtype=float) * SPACING
    bonds = []
    for a in range(len(idx)):
        for b in range(a + 1, len(idx)):
            d = np.subtract(idx[a], idx[b])
            if 1 <= int(np.dot(d, d)) <= 2:
                bonds.append((a, b, float(np.linalg.norm(pos[a] - pos[b]))))
    return pos, bonds


def forces(q, bonds_a, bonds_b, rest):
    d = q[bonds_a] - q[bonds_b]
    r = np.linalg.norm(d, axis=1)
    f = (-STIFFNESS * (r - rest) / r)[:, None] * d
    out = np.zeros_like(q)
    np.add.at(out, bonds_a, f)
    np.add.at(out, bonds_b, -f)
    return out


def energy(q, v, bonds_a, bonds_b, rest):
    r = np.linalg.norm(q[bonds_a] - q[bonds_b], axis=1)
    return 0.5 * MASS * np.sum(v * v) + 0.5 * STIFFNESS * np.sum((r - rest) ** 2)


def trajectory(rng, q0, bonds, states):
    a_idx = np.array([b[0] for b in bonds])
    b_idx = np.array([b[1] for b in bonds])
    rest = np.array([b[2] for b in bonds])
    q = q0 + rng.normal(0.0, 0.04 * SPACING, q0.shape)
    v = rng.normal(0.0, 0.1, q0.shape)
    v -= v.mean(axis=0)
    acc = forces(q, a_idx, b_idx, rest) / MASS
    e0 = energy(q, v, a_idx, b_idx, rest)
    out = [(q.copy(), v.copy())]
    for _ in range(states - 1):
        for _ in range(EVERY):
            v_half = v + 0.5 * DT * acc
            q = q + DT * v_half
            acc = forces(q, a_idx, b_idx, rest) / MASS
            v = v_half + 0.5 * DT * acc
        out.append((q.copy(), v.copy()))
    drift = abs(energy(q, v, a_idx, b_idx, rest) - e0) / e0
    momentum = np.abs(MASS * v.sum(axis=0)).max()
    return out, drift, momentum


def typestore():
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_KILTED)
    text = (Path(__file__).resolve().parent.parent / "msg" / "ParticleState.msg").read_text()
    store.register(get_types_from_msg(text, "mcgnode_msgs/msg/ParticleState"))
    return store


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--side", type=int, default=3)
    ap.add_argument("--trajectories", type=int, default=30)
    ap.add_argument("--states", type=int, default=100)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--storage", choices=["mcap", "sqlite3"], default="mcap")
    args = ap.parse_args()
    if args.side < 2:
        sys.exit("--side must be at least 2")

    from rosbags.rosbag2 import StoragePlugin, Writer

    store = typestore()
    T = "mcgnode_msgs/msg/ParticleState"
    PS = store.types[T]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    V3 = store.types["geometry_msgs/msg/Vector3"]

    q0, bonds = lattice(args.side)
    n = len(q0)
    rng = np.random.default_rng(args.seed)
    plugin = StoragePlugin.MCAP if args.storage == "mcap" else StoragePlugin.SQLITE3
    writer = Writer(args.out, version=9, storage_plugin=plugin)
    writer.open()
    conn = writer.add_connection("/lattice/state", T, typestore=store)
    worst = 0.0
    for tid in range(args.trajectories):
        states, drift, momentum = trajectory(rng, q0, bonds, args.states)
        worst = max(worst, drift)
        if drift > 1e-6 or momentum > 1e-9:
            sys.exit(f"trajectory {tid}: energy drift {drift:.2e}, momentum {momentum:.2e}")
        for step, (q, v) in enumerate(states):
            t = tid * 1000.0 + step * DT * EVERY
            ns = int(round(t * 1e9))
            msg = PS(
                header=Header(stamp=Time(sec=ns // 10**9, nanosec=ns % 10**9), frame_id="lattice"),
                trajectory_id=tid,
                step=step,
                system="harmonic-lattice",
                dimension=3,
                types=np.zeros(n, dtype=np.uint32),
                masses=np.full(n, MASS),
                positions=[V3(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in q],
                velocities=[V3(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in v],
                accelerations=[],
                edge_a=np.array([b[0] for b in bonds], dtype=np.uint32),
                edge_b=np.array([b[1] for b in bonds], dtype=np.uint32),
                edge_kind=np.zeros(len(bonds), dtype=np.uint8),
                edge_rest_length=np.array([b[2] for b in bonds]),
                edge_stiffness=np.full(len(bonds), STIFFNESS),
                anchors=[],
                field_status=1,
                gravity=V3(x=0.0, y=0.0, z=0.0),
                drag=0.0,
                force=V3(x=0.0, y=0.0, z=0.0),
                interaction_radius=0.0,
                kinematic=np.zeros(0, dtype=bool),
                box_lower=V3(x=0.0, y=0.0, z=0.0),
                box_upper=V3(x=0.0, y=0.0, z=0.0),
                box_periodic=np.zeros(0, dtype=bool),
            )
            writer.write(conn, ns, bytes(store.serialize_cdr(msg, T)))
    writer.close()
    print(
        f"{args.out}: {args.trajectories} trajectories of a {n}-particle lattice, {len(bonds)} bonds, "
        f"{args.states} states every {DT * EVERY:g} s; worst energy drift {worst:.1e}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
