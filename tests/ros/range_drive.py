#!/usr/bin/env python3
"""Sends the node states its model cannot vouch for, with real rclpy.

Run by tests/ros_node.rs inside scripts/netns.sh next to `mcgnode serve` serving
a spring MCGNODE trained without --edge-physics (its file records its training
edges and input scales). Every wait is bounded. Exits 1 with "FAIL: ..." on the
first failed check; on success prints `RANGE_SUMMARY {json}`.

Checks, in order (none of these states is accepted silently):
  * a plain spring state is predicted, out_of_range stays 0;
  * velocities of 1e3 (far beyond out_of_range_sigmas) are predicted anyway
    but counted in NodeDiagnostics.out_of_range and warned about on /rosout;
  * velocities of 1e300 are refused by default (an absurd state), with the
    reason, counted as rejected, and not predicted;
  * a spring of stiffness 5, one of rest length 2 and one of stiffness -1 are
    rejected (the model cannot see edges), naming --edge-physics;
  * with out_of_range_refuse set at run time, 1e3 velocities are rejected;
  * every prediction published is finite and keeps its input's total
    momentum (the model is a closed MCGNODE: the node refuses one that does
    not, "refused (broke conservation)").
"""

import argparse
import json
import math
import os
import random
import sys
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import drive  # noqa: E402  (its state builders and checks; importing it loads rclpy, runs nothing)

from builtin_interfaces.msg import Time  # noqa: E402
from mcgnode_msgs.msg import NodeDiagnostics, PredictedTrajectory, ParticleState  # noqa: E402
from rcl_interfaces.msg import Log  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rclpy.parameter_client import AsyncParameterClient  # noqa: E402

rclpy = drive.rclpy


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--timeout", type=float, default=20.0)
    a = ap.parse_args()
    rclpy.init()
    node = rclpy.create_node("range_drive")
    trajs, diags, logs = {}, [], []
    node.create_subscription(PredictedTrajectory, "/mcgnode/predicted_trajectory",
                             lambda m: trajs.__setitem__(m.header.stamp.sec, m), 10)
    node.create_subscription(NodeDiagnostics, "/mcgnode/diagnostics", diags.append, 10)
    node.create_subscription(Log, "/rosout", logs.append, 100)
    pub = node.create_publisher(ParticleState, "/particle_state", 10)
    rng = random.Random(5)

    def wait(pred, what, timeout=a.timeout):
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            rclpy.spin_once(node, timeout_sec=0.05)
            if pred():
                return
        raise drive.Fail(f"timed out waiting for {what}")

    def last():
        return diags[-1] if diags else None

    def send(sec, change=None):
        m = drive.spring_state(rng, 5, Time(sec=sec, nanosec=0))
        if change:
            change(m)
        pub.publish(m)

    wait(lambda: pub.get_subscription_count() >= 1, "the node's input subscription")
    wait(lambda: len(diags) >= 1, "NodeDiagnostics")

    send(1)
    wait(lambda: 1 in trajs, "a prediction of a plain state")
    wait(lambda: last().predicted >= 1, "the plain prediction in the diagnostics")
    drive.check(last().out_of_range == 0, f"a plain state counted out of range: {last()}")

    def fast(m):
        for v in m.velocities:
            v.x = v.y = 1e3
    send(2, fast)
    wait(lambda: 2 in trajs, "the prediction of an out-of-range state (predicted with a warning)")
    wait(lambda: last().out_of_range >= 1, "out_of_range counted")
    wait(lambda: any("out-of-range input" in g.msg and "velocity" in g.msg for g in logs),
         "an out-of-range warning on /rosout")

    def absurd(m):
        for v in m.velocities:
            v.x = v.y = 1e300
    rejected_a = last().rejected
    send(10, absurd)
    wait(lambda: last().rejected >= rejected_a + 1, "a 1e300 state refused by default")
    drive.check("absurd state" in last().last_error, f"last_error {last().last_error!r}")

    rejected0 = last().rejected
    bad_edges = {
        3: lambda m: m.edge_stiffness.__setitem__(0, 5.0),
        4: lambda m: m.edge_rest_length.__setitem__(1, 2.0),
        5: lambda m: m.edge_stiffness.__setitem__(2, -1.0),
    }
    for sec, change in bad_edges.items():
        send(sec, change)
    wait(lambda: last().rejected >= rejected0 + len(bad_edges), "the unseen edges rejected")
    drive.check("--edge-physics" in last().last_error, f"last_error {last().last_error!r}")
    # A plain state after them is still answered, so the rejected ones had
    # their turn: none of them was predicted.
    send(6)
    wait(lambda: 6 in trajs, "a prediction after the rejections")
    drive.check(not any(s in trajs for s in bad_edges), "a state with an unseen edge was predicted")
    drive.check(10 not in trajs, "a 1e300 state was predicted")

    client = AsyncParameterClient(node, "mcgnode")
    drive.check(client.wait_for_services(timeout_sec=a.timeout), "no parameter services")
    fut = client.set_parameters([Parameter("out_of_range_refuse", Parameter.Type.BOOL, True)])
    rclpy.spin_until_future_complete(node, fut, timeout_sec=a.timeout)
    drive.check(fut.done() and fut.result().results[0].successful, "setting out_of_range_refuse failed")
    rejected1, oor1 = last().rejected, last().out_of_range
    send(7, fast)
    wait(lambda: last().rejected >= rejected1 + 1 and last().out_of_range >= oor1 + 1,
         "an out-of-range state refused")
    drive.check("out_of_range_refuse" in last().last_error, f"last_error {last().last_error!r}")
    send(8)
    wait(lambda: 8 in trajs, "a prediction after the refusal")
    drive.check(7 not in trajs, "a refused out-of-range state was predicted")

    # Nothing absurd published: every prediction is finite and, the model being
    # a closed MCGNODE, keeps its input's total momentum (to 1e-6 of sum |m v|).
    for sec, t in trajs.items():
        ms, vs = list(t.initial.masses), list(t.velocities)
        n, steps = len(ms), t.steps
        drive.check(steps > 0 and len(vs) % (steps * n) == 0, f"prediction {sec}: layout")
        d = len(vs) // (steps * n)
        drive.check(all(math.isfinite(x) for x in vs), f"prediction {sec} is not finite")
        v0 = [(v.x, v.y, v.z)[:d] for v in t.initial.velocities]
        p0 = [sum(m * v[c] for m, v in zip(ms, v0)) for c in range(d)]
        s0 = sum(m * math.hypot(*v) for m, v in zip(ms, v0))
        for k in range(steps):
            row = vs[k * n * d:(k + 1) * n * d]
            vk = [row[i * d:(i + 1) * d] for i in range(n)]
            pk = [sum(m * v[c] for m, v in zip(ms, vk)) for c in range(d)]
            sk = sum(m * math.hypot(*v) for m, v in zip(ms, vk))
            drift = math.dist(p0, pk)
            drive.check(drift <= 1e-6 * max(s0, sk),
                        f"prediction {sec}, state {k}: momentum drifts {drift:.3e}")

    d = last()
    print("RANGE_SUMMARY " + json.dumps({"received": d.received, "rejected": d.rejected,
                                         "predicted": d.predicted, "out_of_range": d.out_of_range}),
          flush=True)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    try:
        main()
    except drive.Fail as e:
        print(f"FAIL: {e}", flush=True)
        sys.exit(1)
