#!/usr/bin/env python3
"""Checks the node's MCAP recording with two independent readers.

Usage: check_recording.py DIR --horizon N --predictions N --received N

Every *.mcap in DIR is decoded with mcap + mcap-ros2-support and with rosbags
(types from the bags' own schemas). Both must see the same messages: `received`
states on the input topic, `predictions` trajectories (each with `horizon`
states, stamped like a recorded input) and as many force messages, and between
1 and `predictions` MarkerArrays (rate-limited by markers_period), each drawing
the particles of the recorded input it is stamped with and the paths of the
trajectory predicted from it. Prints `RECORDING {json}`; exits 1 with
"FAIL: ..." otherwise.
"""

import argparse
import json
import sys
from collections import Counter
from pathlib import Path

STATE = "mcgnode_msgs/msg/ParticleState"
TRAJ = "mcgnode_msgs/msg/PredictedTrajectory"
FORCES = "mcgnode_msgs/msg/ParticleForces"
MARKERS = "visualization_msgs/msg/MarkerArray"


def xyz(p):
    return (float(p.x), float(p.y), float(p.z))


def check_markers(arr, inputs, trajs):
    """One recorded MarkerArray against the input and trajectory it draws."""
    ms = list(arr.markers)
    if not ms or ms[0].action != 3:
        raise SystemExit("FAIL: a MarkerArray does not start with DELETEALL")
    by_ns = {m.ns: m for m in ms[1:]}
    parts = by_ns.get("particles")
    if parts is None or parts.type != 7:
        raise SystemExit(f"FAIL: no SPHERE_LIST of particles among {sorted(by_ns)}")
    s = inputs.get(stamp(parts))
    if s is None:
        raise SystemExit(f"FAIL: markers stamped {stamp(parts)} match no recorded input")
    if [xyz(p) for p in parts.points] != [xyz(p) for p in s.positions]:
        raise SystemExit("FAIL: the particles marker is not at the input's positions")
    paths = by_ns.get("predicted_paths")
    t = trajs.get(stamp(parts))
    if paths is None or t is None:
        raise SystemExit("FAIL: no predicted paths, or no trajectory for the markers' input")
    n, d = len(s.positions), s.dimension
    ends = [xyz(p) for p in paths.points[1::2]]
    last = [float(x) for x in t.positions[len(t.positions) - n * d:]]
    if ends[-n:] != [tuple(last[i:i + d] + [0.0] * (3 - d)) for i in range(0, n * d, d)]:
        raise SystemExit("FAIL: the predicted paths do not end at the trajectory's last state")
    if not any(m.ns == "forces" for m in ms):
        raise SystemExit("FAIL: no force markers")


def stamp(m):
    return (int(m.header.stamp.sec), int(m.header.stamp.nanosec))


def summarize(items, horizon):
    """items: (schema name, message) pairs -> comparable summary."""
    counts = Counter(name for name, _ in items)
    inputs = {stamp(m) for name, m in items if name == STATE}
    trajs = [m for name, m in items if name == TRAJ]
    by_stamp = {stamp(m): m for name, m in items if name == STATE}
    traj_by_stamp = {stamp(t): t for t in trajs}
    for name, m in items:
        if name == MARKERS:
            check_markers(m, by_stamp, traj_by_stamp)
    for t in trajs:
        n, d = len(t.initial.positions), t.initial.dimension
        if t.steps != horizon or len(t.positions) != horizon * n * d or len(t.velocities) != horizon * n * d:
            raise SystemExit(f"FAIL: recorded trajectory has {t.steps} states ({len(t.positions)} "
                             f"coordinates of {n} particles in {d}D), horizon {horizon}")
        if stamp(t) not in inputs:
            raise SystemExit(f"FAIL: recorded trajectory stamped {stamp(t)} matches no recorded input")
    return {
        "counts": dict(sorted(counts.items())),
        "trajectory_stamps": sorted(stamp(t) for t in trajs),
        "forces_stamps": sorted(stamp(m) for name, m in items if name == FORCES),
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("dir", type=Path)
    ap.add_argument("--horizon", type=int, required=True)
    ap.add_argument("--predictions", type=int, required=True)
    ap.add_argument("--received", type=int, required=True)
    args = ap.parse_args()
    bags = sorted(args.dir.glob("*.mcap"))
    if not bags:
        raise SystemExit(f"FAIL: no .mcap files in {args.dir}")

    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    via_mcap, via_rosbags = [], []
    for bag in bags:
        with open(bag, "rb") as fh:
            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            for schema, _ch, _msg, m in reader.iter_decoded_messages(log_time_order=True):
                via_mcap.append((schema.name, m))
        with AnyReader([bag]) as r:
            for conn, _t, raw in r.messages():
                via_rosbags.append((conn.msgtype, r.deserialize(raw, conn.msgtype)))

    a, b = summarize(via_mcap, args.horizon), summarize(via_rosbags, args.horizon)
    if a != b:
        raise SystemExit(f"FAIL: the readers disagree:\nmcap: {a}\nrosbags: {b}")
    markers = a["counts"].pop(MARKERS, 0)
    if not 1 <= markers <= args.predictions:
        raise SystemExit(f"FAIL: {markers} MarkerArrays recorded for {args.predictions} predictions")
    want = {STATE: args.received, TRAJ: args.predictions, FORCES: args.predictions}
    if a["counts"] != dict(sorted(want.items())):
        raise SystemExit(f"FAIL: recorded {a['counts']}, expected {want}")
    a["counts"][MARKERS] = markers
    if a["trajectory_stamps"] != a["forces_stamps"]:
        raise SystemExit("FAIL: trajectories and forces were recorded for different inputs")
    print("RECORDING " + json.dumps({"bags": len(bags), "counts": a["counts"]}))


if __name__ == "__main__":
    main()
