#!/usr/bin/env python3
"""Listens to the node's live accuracy while a bag is played (run by
tests/ros_accuracy.rs inside scripts/netns.sh next to `mcgnode serve` with
accuracy_lead_times set).

Subscribes to /mcgnode/live_accuracy (mcgnode_msgs/LiveAccuracy) and
/diagnostics (diagnostic_msgs/DiagnosticArray), says `listening` on stderr
once both have matched the node, and records every LiveAccuracy message and
every `mcgnode: live accuracy` status with the monotonic time it arrived
(and every `mcgnode: spread` status); with --predictions also the stamp and
largest spread of every PredictedTrajectory.
Stops after --count LiveAccuracy messages (then one more /diagnostics period,
--linger s) or --timeout s. Prints `ACCURACY_SUMMARY {json}`; exits 1 with
`FAIL: ...` when it times out first.
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
from mcgnode_msgs.msg import LiveAccuracy, PredictedTrajectory  # noqa: E402
try:
    from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
except ImportError:
    print("FAIL: diagnostic_msgs is not installed in the venv; run scripts/setup_venv.sh", flush=True)
    sys.exit(1)


def level_of(x):
    return int.from_bytes(x, "little") if isinstance(x, bytes) else int(x)


def finite(xs):
    return [x if math.isfinite(x) else None for x in xs]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--count", type=int, required=True)
    ap.add_argument("--timeout", type=float, default=60.0)
    ap.add_argument("--linger", type=float, default=0.6)
    ap.add_argument("--predictions", action="store_true",
                    help="also record each prediction's stamp and largest spread")
    a = ap.parse_args()
    rclpy.init()
    node = rclpy.create_node("accuracy_drive")
    live, diags, spread_diags, predictions = [], [], [], []

    def on_live(m):
        live.append({
            "t": time.monotonic(),
            "stamp": m.header.stamp.sec + m.header.stamp.nanosec * 1e-9,
            "level": level_of(m.level),
            "message": m.message,
            "lead_times": list(m.lead_times),
            "compared": list(m.compared),
            "re": finite(m.re),
            "re_mean": finite(m.re_mean),
            "ee_mean": finite(m.ee_mean),
        })

    def on_diag(m):
        for s in m.status:
            if s.name.endswith("live accuracy"):
                diags.append({"t": time.monotonic(), "level": level_of(s.level), "message": s.message,
                              "values": {kv.key: kv.value for kv in s.values}})
            elif s.name.endswith(": spread"):
                spread_diags.append({"t": time.monotonic(), "level": level_of(s.level), "message": s.message})

    def on_prediction(m):
        spread = list(m.spread)
        predictions.append({
            "t": time.monotonic(),
            "stamp": m.header.stamp.sec + m.header.stamp.nanosec * 1e-9,
            "spread_max": max(spread) if spread else None,
            "spread_count": len(spread),
        })

    sub_live = node.create_subscription(LiveAccuracy, "/mcgnode/live_accuracy", on_live, 100)
    sub_diag = node.create_subscription(DiagnosticArray, "/diagnostics", on_diag, 10)
    if a.predictions:
        node.create_subscription(PredictedTrajectory, "/mcgnode/predicted_trajectory", on_prediction, 100)
    start = time.monotonic()
    left = lambda: max(0.0, a.timeout - (time.monotonic() - start))  # noqa: E731
    if not ru.spin_until(rclpy, node, lambda: sub_live.get_publisher_count() >= 1
                         and sub_diag.get_publisher_count() >= 1, left()):
        print("FAIL: the node's live accuracy and /diagnostics never matched", flush=True)
        sys.exit(1)
    print("accuracy_drive: listening", file=sys.stderr, flush=True)
    done = ru.spin_until(rclpy, node, lambda: len(live) >= a.count, left(), step=0.02)
    ru.spin_until(rclpy, node, lambda: False, min(a.linger, left()), step=0.02)
    node.destroy_node()
    rclpy.try_shutdown()
    print("ACCURACY_SUMMARY " + json.dumps({"live": live, "diagnostics": diags, "spread_diagnostics": spread_diags,
                                               "predictions": predictions}), flush=True)
    if not done:
        print(f"FAIL: {len(live)} of {a.count} LiveAccuracy messages within {a.timeout} s", flush=True)
        sys.exit(1)


if __name__ == "__main__":
    main()
