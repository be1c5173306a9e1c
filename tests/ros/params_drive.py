#!/usr/bin/env python3
"""Drives the node's ROS parameters from rclpy (run by tests/ros_params.rs
inside scripts/netns.sh next to `mcgnode serve --params ...` with horizon 25).

Lists and gets every parameter, sets a run-time parameter (horizon) and checks
the next prediction follows it, and checks that a read-only parameter, an
out-of-range value and an ill-typed value are refused with a reason. Prints
`PARAMS_SUMMARY {json}`; exits 1 with `FAIL: ...` otherwise. Every wait is
bounded by --timeout.
"""

import argparse
import json
import os
import random
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "ros"))
import _rosutil as ru  # noqa: E402
import bench_large  # noqa: E402

rclpy = ru.require_rclpy()
from builtin_interfaces.msg import Time  # noqa: E402
from mcgnode_msgs.msg import ParticleState, PredictedTrajectory  # noqa: E402
try:
    from diagnostic_msgs.msg import DiagnosticArray  # noqa: E402
except ImportError:
    print("FAIL: diagnostic_msgs is not installed in the venv; run scripts/setup_venv.sh", flush=True)
    sys.exit(1)
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.parameter_client import AsyncParameterClient  # noqa: E402


def fail(msg):
    print(f"FAIL: {msg}", flush=True)
    sys.exit(1)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--timeout", type=float, default=20.0)
    a = ap.parse_args()
    rclpy.init()
    node = rclpy.create_node("params_drive")
    trajs = {}
    node.create_subscription(PredictedTrajectory, "/mcgnode/predicted_trajectory",
                             lambda m: trajs.__setitem__(m.header.stamp.sec, m), 10)
    pub = node.create_publisher(ParticleState, "/particle_state", 10)
    diags = []
    node.create_subscription(DiagnosticArray, "/diagnostics", diags.append, 10)
    client = AsyncParameterClient(node, "mcgnode")
    if not client.wait_for_services(timeout_sec=a.timeout):
        fail("the node's parameter services are not available")

    def call(fut, what):
        rclpy.spin_until_future_complete(node, fut, timeout_sec=a.timeout)
        if not fut.done():
            fail(f"no answer to {what} within {a.timeout} s")
        return fut.result()

    names = list(call(client.list_parameters(), "list_parameters").result.names)
    for want in ("substeps", "model_dir", "max_particles", "horizon", "dt", "use_sim_time"):
        if want not in names:
            fail(f"{want} not listed: {names}")
    # describe_parameters (`ros2 param describe`) gives the one table's text,
    # ranges and which parameters are read-only.
    desc = {d.name: d for d in call(client.describe_parameters(["horizon", "input_topic", "dt"]),
                                    "describe_parameters").descriptors}
    h, t, d = desc["horizon"], desc["input_topic"], desc["dt"]
    if h.description != "steps predicted per incoming state" or h.read_only:
        fail(f"horizon described as {h}")
    if [(r.from_value, r.to_value, r.step) for r in h.integer_range] != [(1, 100000, 1)]:
        fail(f"horizon range {h.integer_range}")
    if not t.read_only or not t.additional_constraints.startswith("a ROS 2 name: absolute (/a), relative"):
        fail(f"input_topic described as {t}")
    if d.additional_constraints != "finite and > 0" or d.floating_point_range[0].from_value != 0.0:
        fail(f"dt described as {d}")
    got = call(client.get_parameters(["horizon", "substeps", "model"]), "get_parameters").values
    before = {"horizon": got[0].integer_value, "substeps": got[1].integer_value, "model": got[2].string_value}

    def set_one(p):
        r = call(client.set_parameters([p]), f"set_parameters {p.name}").results[0]
        return r.successful, r.reason

    results = {
        "horizon=7": set_one(Parameter("horizon", Parameter.Type.INTEGER, 7)),
        "qos_depth=3": set_one(Parameter("qos_depth", Parameter.Type.INTEGER, 3)),
        "dt=-1": set_one(Parameter("dt", Parameter.Type.DOUBLE, -1.0)),
        "max_particles=0": set_one(Parameter("max_particles", Parameter.Type.INTEGER, 0)),
    }
    after = call(client.get_parameters(["horizon", "qos_depth"]), "get_parameters").values

    # The next prediction follows the new horizon.
    if not ru.spin_until(rclpy, node, lambda: pub.get_subscription_count() > 0, a.timeout):
        fail("the node's input never matched")
    state = bench_large.ring(random.Random(3), 5)
    states = None
    for sec in range(100, 100 + 50):
        state.header.stamp = Time(sec=sec, nanosec=0)
        pub.publish(state)
        if ru.spin_until(rclpy, node, lambda: sec in trajs, 0.2, step=0.01):
            states = trajs[sec].steps
            break
    if states is None:
        fail("no prediction after setting horizon")
    # /diagnostics: OK while all is well; WARN after a rejected (malformed) state.
    def next_diag():
        n = len(diags)
        if not ru.spin_until(rclpy, node, lambda: len(diags) > n, a.timeout):
            fail("no DiagnosticArray on /diagnostics")
        s = diags[-1].status[0]
        return {"level": int.from_bytes(s.level, "little") if isinstance(s.level, bytes) else int(s.level),
                "name": s.name, "message": s.message, "values": {kv.key: kv.value for kv in s.values}}

    next_diag()
    ok_diag = next_diag()
    bad = bench_large.ring(random.Random(4), 5)
    bad.masses = bad.masses[:3]
    bad.header.stamp = Time(sec=999, nanosec=0)
    pub.publish(bad)
    warn_diag = next_diag()
    if warn_diag["level"] == 0:
        warn_diag = next_diag()
    summary = {"ok_diag": ok_diag, "warn_diag": warn_diag, "listed": len(names), "before": before,
               "results": {k: {"successful": s, "reason": r} for k, (s, r) in results.items()},
               "horizon_after": after[0].integer_value, "qos_depth_after": after[1].integer_value,
               "predicted_states": states}
    print("PARAMS_SUMMARY " + json.dumps(summary), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
