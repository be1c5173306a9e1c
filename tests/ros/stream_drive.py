#!/usr/bin/env python3
"""Listens to the node while bags are played into it (run by
tests/ros_stream.rs inside scripts/netns.sh beside `mcgnode serve`).

Subscribes to /mcgnode/predicted_trajectory, /mcgnode/live_accuracy and
/mcgnode/diagnostics, says `listening` on stderr once all three have matched
the node, then records until a file named by --stop exists (and one more
diagnostics period) or --timeout s pass. Prints `STREAM_SUMMARY {json}`:
every LiveAccuracy message in arrival order, the number of predictions, how
many carried a non-finite number, the velocities of the first prediction's
initial state per trajectory run, and the last NodeDiagnostics.
"""

import argparse
import json
import math
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "ros"))
import _rosutil as ru  # noqa: E402

rclpy = ru.require_rclpy()
from mcgnode_msgs.msg import LiveAccuracy, NodeDiagnostics, PredictedTrajectory  # noqa: E402


def finite(xs):
    return [x if math.isfinite(x) else None for x in xs]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--stop", required=True, help="stop once this file exists")
    ap.add_argument("--timeout", type=float, default=90.0)
    a = ap.parse_args()
    rclpy.init()
    node = rclpy.create_node("stream_drive")
    live, out = [], {"predicted": 0, "non_finite": 0, "initial": [], "diagnostics": None}

    def on_traj(m):
        out["predicted"] += 1
        nums = list(m.positions) + list(m.velocities)
        nums += [c for v in m.initial.velocities for c in (v.x, v.y, v.z)]
        if not all(math.isfinite(x) for x in nums):
            out["non_finite"] += 1
        out["initial"].append({
            "stamp": m.header.stamp.sec + m.header.stamp.nanosec * 1e-9,
            "velocities": [[v.x, v.y] for v in m.initial.velocities],
        })

    def on_live(m):
        live.append({
            "trajectory_id": m.trajectory_id,
            "stamp": m.header.stamp.sec + m.header.stamp.nanosec * 1e-9,
            "compared": list(m.compared),
            "re": finite(m.re),
            "re_mean": finite(m.re_mean),
            "level": int.from_bytes(m.level, "little") if isinstance(m.level, bytes) else int(m.level),
        })

    def on_diag(m):
        out["diagnostics"] = {k: getattr(m, k) for k in (
            "received", "rejected", "predicted", "derived", "warming_up", "history_resets", "last_error")}

    qos = ru.qos_profile(reliable=True, depth=1000)
    subs = [
        node.create_subscription(PredictedTrajectory, "/mcgnode/predicted_trajectory", on_traj, qos),
        node.create_subscription(LiveAccuracy, "/mcgnode/live_accuracy", on_live, qos),
        node.create_subscription(NodeDiagnostics, "/mcgnode/diagnostics", on_diag, 10),
    ]
    start = time.monotonic()
    left = lambda: max(0.0, a.timeout - (time.monotonic() - start))  # noqa: E731
    if not ru.spin_until(rclpy, node, lambda: all(s.get_publisher_count() >= 1 for s in subs), left()):
        print("FAIL: the node's topics never matched", flush=True)
        sys.exit(1)
    print("stream_drive: listening", file=sys.stderr, flush=True)
    stopped = ru.spin_until(rclpy, node, lambda: os.path.exists(a.stop), left(), step=0.02)
    # One more diagnostics period, so the counters include the last states.
    ru.spin_until(rclpy, node, lambda: False, min(1.5, left()), step=0.02)
    node.destroy_node()
    rclpy.try_shutdown()
    out["live"] = live
    print("STREAM_SUMMARY " + json.dumps(out), flush=True)
    if not stopped:
        print(f"FAIL: not told to stop within {a.timeout} s", flush=True)
        sys.exit(1)


if __name__ == "__main__":
    main()
