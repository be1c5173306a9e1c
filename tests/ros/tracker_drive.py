#!/usr/bin/env python3
"""Publishes a tracker's stream into a running `mcgnode serve` and measures
what comes back (run by tests/ros_tracker.rs inside scripts/netns.sh).

  --mode state: the states of --states (a JSON list of ParticleState as
                plain dicts) as ParticleState on /particle_state;
  --mode pose:  their positions as geometry_msgs/PoseArray on --topic;
  --mode cloud: their positions as sensor_msgs/PointCloud2 (x, y, z float32,
                an extra intensity field, point_step 16) on --topic.

Publishers are best effort (as trackers and SensorDataQoS publish; reliable
with --reliable), at --rate
Hz, each message stamped with its state's stamp. With --malformed, after
every --every-th good message one malformed message (of a list that differs
per mode) is published. Listens to /mcgnode/predicted_trajectory (reliable)
and /mcgnode/diagnostics; a prediction is matched to its input by stamp, and
its latency is its arrival minus the input's publish time. Prints
`TRACKER_SUMMARY {json}`: published, malformed sent, predictions matched,
latencies (ms) p50/p99/max after warm-up, the last NodeDiagnostics, and the
values of the last /diagnostics `predictions` status (`standard`).
"""

import argparse
import json
import math
import os
import struct
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "ros"))
import _rosutil as ru  # noqa: E402

rclpy = ru.require_rclpy()
from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import Pose, PoseArray  # noqa: E402
from mcgnode_msgs.msg import NodeDiagnostics, ParticleState, PredictedTrajectory  # noqa: E402
from sensor_msgs.msg import PointCloud2, PointField  # noqa: E402
try:
    from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
except ImportError:
    print("FAIL: diagnostic_msgs is not installed in the venv; run scripts/setup_venv.sh", flush=True)
    sys.exit(1)


def stamp_of(d):
    return (int(d["header"]["stamp"]["sec"]), int(d["header"]["stamp"]["nanosec"]))


def pose_array(d, frame, points=None):
    m = PoseArray()
    m.header.stamp = Time(sec=stamp_of(d)[0], nanosec=stamp_of(d)[1])
    m.header.frame_id = frame
    for p in points if points is not None else d["positions"]:
        pose = Pose()
        pose.position.x, pose.position.y, pose.position.z = float(p["x"]), float(p["y"]), float(p["z"])
        pose.orientation.w = 1.0
        m.poses.append(pose)
    return m


def fields(spec):
    """PointFields from [(name, offset, datatype)]: 7 = FLOAT32, 8 = FLOAT64."""
    return [PointField(name=n, offset=o, datatype=t, count=1) for n, o, t in spec]


XYZI = [("x", 0, 7), ("y", 4, 7), ("z", 8, 7), ("intensity", 12, 7)]


def cloud(d, frame, points=None, spec=XYZI, step=16, big=False, height=1, data=None, width=None):
    pts = points if points is not None else d["positions"]
    m = PointCloud2()
    m.header.stamp = Time(sec=stamp_of(d)[0], nanosec=stamp_of(d)[1])
    m.header.frame_id = frame
    m.height = height
    m.width = width if width is not None else len(pts) // max(height, 1)
    m.fields = fields(spec)
    m.is_bigendian = big
    m.point_step = step
    m.row_step = step * m.width
    if data is None:
        buf = bytearray(step * len(pts))
        end = ">" if big else "<"
        for i, p in enumerate(pts):
            for name, off, dt in spec:
                v = float(p.get(name, 1.0)) if name in "xyz" else 1.0
                if off + (4 if dt == 7 else 8) <= step:
                    struct.pack_into(end + ("f" if dt == 7 else "d"), buf, i * step + off, v)
        data = bytes(buf)
    m.data = data
    m.is_dense = True
    return m


def malformed_poses(d, frame):
    """Each refused for its own reason (tests/ros_tracker.rs checks the counts)."""
    pts = d["positions"]
    nan = dict(pts[0], x=float("nan"))
    inf = dict(pts[0], y=float("inf"))
    return [
        pose_array(d, frame, pts[:-1]),
        pose_array(d, frame, pts + pts[:1]),
        pose_array(d, frame, []),
        pose_array(d, frame, [nan] + pts[1:]),
        pose_array(d, frame, [inf] + pts[1:]),
        pose_array(d, "camera", pts),
        pose_array(d, "", pts),
    ]


def malformed_clouds(d, frame):
    pts = d["positions"]
    good = cloud(d, frame)
    return [
        cloud(d, frame, pts[:-1]),
        cloud(d, "camera"),
        cloud(d, frame, spec=[("x", 0, 7), ("y", 4, 7)], step=8),
        cloud(d, frame, spec=[("x", 0, 7), ("y", 4, 7), ("z", 8, 2)]),
        cloud(d, frame, step=8),
        cloud(d, frame, data=good.data[:-5]),
        cloud(d, frame, points=[dict(pts[0], z=float("nan"))] + pts[1:]),
        cloud(d, frame, height=0, width=len(pts)),
    ]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--mode", choices=["state", "pose", "cloud"], required=True)
    ap.add_argument("--states", required=True, help="JSON list of ParticleState dicts")
    ap.add_argument("--topic", default="/particle_state")
    ap.add_argument("--frame", default="world")
    ap.add_argument("--rate", type=float, default=100.0)
    ap.add_argument("--warmup", type=int, default=20, help="states left out of the latencies")
    ap.add_argument("--malformed", action="store_true")
    ap.add_argument("--reliable", action="store_true", help="a reliable publisher (default best effort)")
    ap.add_argument("--every", type=int, default=5)
    ap.add_argument("--timeout", type=float, default=60.0)
    a = ap.parse_args()
    with open(a.states) as f:
        states = json.load(f)
    rclpy.init()
    node = rclpy.create_node("tracker_drive")
    best_effort = ru.qos_profile(reliable=a.reliable, depth=10)
    msg_type = {"state": ParticleState, "pose": PoseArray, "cloud": PointCloud2}[a.mode]
    pub = node.create_publisher(msg_type, a.topic, best_effort)
    sent, arrived = {}, {}
    out = {"diagnostics": None, "standard": None, "worst_position_error": 0.0, "frames": []}
    by_stamp = {stamp_of(d): d for d in states}

    def on_traj(m):
        key = (m.header.stamp.sec, m.header.stamp.nanosec)
        arrived.setdefault(key, time.monotonic())
        if m.header.frame_id not in out["frames"]:
            out["frames"].append(m.header.frame_id)
        # The prediction starts where the tracker said the particles are (a
        # poly smoother would fit them; the default takes them as they are).
        d = by_stamp.get(key)
        if d is not None:
            worst = max((abs(getattr(p, a) - float(q[a])) for p, q in zip(m.initial.positions, d["positions"])
                         for a in "xyz"), default=1e9)
            if len(m.initial.positions) != len(d["positions"]):
                worst = 1e9
            out["worst_position_error"] = max(out["worst_position_error"], worst)

    def on_diag(m):
        out["diagnostics"] = {k: getattr(m, k) for k in (
            "received", "rejected", "predicted", "derived", "warming_up", "last_error")}

    def on_standard(m):
        for st in m.status:
            if st.name.endswith("predictions"):
                out["standard"] = {kv.key: kv.value for kv in st.values}

    node.create_subscription(DiagnosticArray, "/diagnostics", on_standard, 10)
    subs = [
        node.create_subscription(PredictedTrajectory, "/mcgnode/predicted_trajectory", on_traj,
                                 ru.qos_profile(reliable=True, depth=100)),
        node.create_subscription(NodeDiagnostics, "/mcgnode/diagnostics", on_diag, 10),
    ]
    start = time.monotonic()
    left = lambda: max(0.0, a.timeout - (time.monotonic() - start))  # noqa: E731
    matched = lambda: pub.get_subscription_count() >= 1 and all(s.get_publisher_count() >= 1 for s in subs)  # noqa: E731
    if not ru.spin_until(rclpy, node, matched, left()):
        print("FAIL: the node's topics never matched", flush=True)
        sys.exit(1)
    # A best-effort subscriber that matched this instant may miss the first
    # sample; give discovery a moment on both sides.
    ru.spin_until(rclpy, node, lambda: False, 0.5)
    bad = {"state": lambda d: [], "pose": malformed_poses, "cloud": malformed_clouds}[a.mode]
    n_bad, period, t0 = 0, 1.0 / a.rate, time.monotonic()
    for k, d in enumerate(states):
        if a.mode == "state":
            msg = ru.fill(ParticleState(), d)
        elif a.mode == "pose":
            msg = pose_array(d, a.frame)
        else:
            msg = cloud(d, a.frame)
        sent[stamp_of(d)] = time.monotonic()
        pub.publish(msg)
        if a.malformed and k % a.every == a.every - 1:
            wrong = bad(d, a.frame)
            if wrong:
                pub.publish(wrong[n_bad % len(wrong)])
                n_bad += 1
        ru.spin_until(rclpy, node, lambda: False, max(0.0, t0 + (k + 1) * period - time.monotonic()),
                      step=0.001)
    # Wait for the last predictions and one more diagnostics period.
    last = stamp_of(states[-1])
    ru.spin_until(rclpy, node, lambda: last in arrived, min(5.0, left()), step=0.01)
    ru.spin_until(rclpy, node, lambda: False, min(1.5, left()), step=0.05)
    order = [stamp_of(d) for d in states]
    lat = sorted((arrived[s] - sent[s]) * 1e3 for s in order[a.warmup:] if s in arrived)

    def pct(q):
        return lat[min(len(lat) - 1, int(math.ceil(q * len(lat))) - 1)] if lat else None

    out.update({
        "published": len(states), "malformed": n_bad,
        "predicted": sum(1 for s in order if s in arrived),
        "predicted_after_warmup": sum(1 for s in order[a.warmup:] if s in arrived),
        "p50_ms": pct(0.5), "p99_ms": pct(0.99), "max_ms": lat[-1] if lat else None,
    })
    node.destroy_node()
    rclpy.try_shutdown()
    print("TRACKER_SUMMARY " + json.dumps(out), flush=True)


if __name__ == "__main__":
    main()
