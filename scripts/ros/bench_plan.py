#!/usr/bin/env python3
"""Times the node's Plan service from rclpy (run by scripts/ros_bench_plan.sh
inside its network namespace): --calls calls of one request (JSON of a Plan
request without its state, planned from the first ParticleState of --bag),
each with its own seed, one at a time.
Prints `PLAN_BENCH {json}`: the median and range of the round trip (request
sent -> response received) and of the node's own planning time (the
response's `seconds`)."""

import argparse
import json
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _rosutil as ru  # noqa: E402

rclpy = ru.require_rclpy()
from rclpy.serialization import deserialize_message  # noqa: E402

from mcgnode_msgs.msg import ParticleState  # noqa: E402
from mcgnode_msgs.srv import Plan  # noqa: E402


def first_state(path):
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        for s, _c, m in make_reader(f).iter_messages(log_time_order=True):
            if s is not None and s.name == "mcgnode_msgs/msg/ParticleState":
                return deserialize_message(m.data, ParticleState)
    raise SystemExit(f"FAIL: no ParticleState in {path}")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--request", required=True)
    ap.add_argument("--bag", required=True)
    ap.add_argument("--calls", type=int, default=20)
    a = ap.parse_args()
    rclpy.init()
    node = rclpy.create_node("bench_plan")
    client = node.create_client(Plan, "/mcgnode/plan")
    if not client.wait_for_service(timeout_sec=20):
        print("FAIL: /mcgnode/plan not available", flush=True)
        return 1
    data = json.load(open(a.request))
    initial = first_state(a.bag)
    trips, server = [], []
    for k in range(a.calls + 1):
        req = ru.fill(Plan.Request(), dict(data, seed=k))
        req.initial = initial
        t0 = time.perf_counter()
        fut = client.call_async(req)
        # Blocked (ru.WAIT_STEP), not polling: a 0.5 ms poll took CPU from the node's two
        # planning threads (its own planning time 24.5 ms against 18.2).
        if not ru.spin_until(rclpy, node, fut.done, 60):
            print("FAIL: no answer within 60 s", flush=True)
            return 1
        trip = time.perf_counter() - t0
        r = fut.result()
        if not r.success:
            print(f"FAIL: {r.message}", flush=True)
            return 1
        if k > 0:  # the first call warms the model's buffers
            trips.append(trip)
            server.append(r.seconds)
    ms = lambda xs: {"median_ms": round(1e3 * statistics.median(xs), 2),
                     "min_ms": round(1e3 * min(xs), 2), "max_ms": round(1e3 * max(xs), 2)}
    print("PLAN_BENCH " + json.dumps({"calls": a.calls, "round_trip": ms(trips), "node_planning": ms(server)}),
          flush=True)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
