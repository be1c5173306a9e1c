#!/usr/bin/env python3
"""With `use_sim_time: true` the node stamps its diagnostics from /clock (run
by tests/ros_params.rs inside scripts/netns.sh next to `mcgnode serve`).

Publishes rosgraph_msgs/Clock at 20 Hz at a fixed simulated time and prints
`CLOCK_SUMMARY {json}` with the stamps of the next NodeDiagnostics and
/diagnostics messages; exits 1 with `FAIL: ...` if they do not come within
--timeout seconds.
"""

import argparse
import json
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "ros"))
import _rosutil as ru  # noqa: E402

rclpy = ru.require_rclpy()
try:
    from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
    from rosgraph_msgs.msg import Clock  # noqa: E402
except ImportError as e:
    print(f"FAIL: {e.name} is not installed in the venv; run scripts/setup_venv.sh", flush=True)
    sys.exit(1)
from builtin_interfaces.msg import Time  # noqa: E402
from mcgnode_msgs.msg import NodeDiagnostics  # noqa: E402


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--sec", type=int, default=4242, help="simulated time published on /clock")
    ap.add_argument("--timeout", type=float, default=20.0)
    a = ap.parse_args()
    rclpy.init()
    node = rclpy.create_node("clock_drive")
    pub = node.create_publisher(Clock, "/clock", 10)
    ours, std = [], []
    node.create_subscription(NodeDiagnostics, "/mcgnode/diagnostics", ours.append, 10)
    node.create_subscription(DiagnosticArray, "/diagnostics", std.append, 10)
    node.create_timer(0.05, lambda: pub.publish(Clock(clock=Time(sec=a.sec, nanosec=0))))
    # The node stamps from the latest /clock: wait for a message stamped at it.
    sim = lambda msgs: any(m.header.stamp.sec == a.sec for m in msgs)  # noqa: E731
    if not ru.spin_until(rclpy, node, lambda: sim(ours) and sim(std), a.timeout):
        print(f"FAIL: no diagnostics stamped {a.sec} s within {a.timeout} s; NodeDiagnostics stamps "
              f"{[m.header.stamp.sec for m in ours][-5:]}, /diagnostics {[m.header.stamp.sec for m in std][-5:]}",
              flush=True)
        return 1
    summary = {"sim_sec": a.sec, "node_diagnostics_sec": [m.header.stamp.sec for m in ours][-3:],
               "diagnostics_sec": [m.header.stamp.sec for m in std][-3:]}
    print("CLOCK_SUMMARY " + json.dumps(summary), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
