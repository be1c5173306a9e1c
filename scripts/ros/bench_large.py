#!/usr/bin/env python3
"""Large predictions through a running `mcgnode serve`, measured from rclpy.

Run by scripts/ros_bench_large.sh (inside scripts/netns.sh next to the node),
or by tests/ros_large.rs. Publishes spring-ring states (with --contacts:
triangular packings touching within radius 1) of --particles particles,
one at a time, each followed by --small 5-particle states, and measures
publish -> receipt of the node's PredictedTrajectory at a subscriber with
rclpy's default QoS (reliable, keep-last 10, default Fast DDS socket buffers).
Trajectories are taken raw (CDR bytes; only the stamp is decoded), so Python's
conversion of a multi-megabyte message is not part of the figure. Optionally
(--rollout) calls the Rollout service with a large state and a small one.

Prints a report and one line `LARGE_JSON {...}`. Every wait is bounded by
--timeout; a prediction that does not arrive in time is counted as lost (its
latency is the bound), and the script exits 1 only if nothing arrives at all.
"""

import argparse
import json
import math
import os
import random
import struct
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _rosutil as ru  # noqa: E402

rclpy = ru.require_rclpy()

from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import Vector3  # noqa: E402
from mcgnode_msgs.msg import NodeDiagnostics, ParticleState, PredictedTrajectory  # noqa: E402
from mcgnode_msgs.srv import Rollout  # noqa: E402

NS = 1_000_000_000


def ring(rng, n):
    """A ring of n unit masses on unit springs, slightly perturbed."""
    radius = 0.5 / math.sin(math.pi / n)
    m = ParticleState()
    m.system = "spring"
    m.dimension = 2
    m.types = [0] * n
    m.masses = [1.0] * n
    m.positions = [
        Vector3(x=radius * math.cos(2 * math.pi * i / n) + rng.uniform(-0.1, 0.1),
                y=radius * math.sin(2 * math.pi * i / n) + rng.uniform(-0.1, 0.1), z=0.0)
        for i in range(n)
    ]
    m.velocities = [Vector3(x=rng.uniform(-0.3, 0.3), y=rng.uniform(-0.3, 0.3), z=0.0) for _ in range(n)]
    m.edge_a = list(range(n))
    m.edge_b = [(i + 1) % n for i in range(n)]
    m.edge_kind = [ParticleState.EDGE_SPRING] * n
    m.edge_rest_length = [1.0] * n
    m.edge_stiffness = [1.0] * n
    return m


def packing(rng, n):
    """n free unit masses on a triangular lattice 0.8 apart (jittered 2 %),
    touching within radius 1: six contacts each inside, no fixed edge (a
    granular packing, for models trained with --radius 1)."""
    side = max(1, math.ceil(math.sqrt(n)))
    h = 0.8 * math.sqrt(3) / 2
    m = ParticleState()
    m.system = "packing"
    m.dimension = 2
    m.types = [0] * n
    m.masses = [1.0] * n
    m.positions = [
        Vector3(x=(k % side) * 0.8 + (0.4 if (k // side) % 2 else 0.0) + rng.uniform(-0.016, 0.016),
                y=(k // side) * h + rng.uniform(-0.016, 0.016), z=0.0)
        for k in range(n)
    ]
    m.velocities = [Vector3(x=rng.uniform(-0.05, 0.05), y=rng.uniform(-0.05, 0.05), z=0.0) for _ in range(n)]
    m.interaction_radius = 1.0
    return m


def percentile(xs, p):
    s = sorted(xs)
    return s[min(len(s) - 1, max(0, math.ceil(p / 100 * len(s)) - 1))] if s else None


def summary(ms):
    if not ms:
        return {"count": 0}
    return {"count": len(ms), "p50_ms": round(percentile(ms, 50), 2), "p99_ms": round(percentile(ms, 99), 2),
            "max_ms": round(max(ms), 2)}


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--particles", type=int, default=1000, help="particles of the large states")
    ap.add_argument("--messages", type=int, default=20, help="large states published")
    ap.add_argument("--small", type=int, default=5, help="5-particle states after each large one")
    ap.add_argument("--rollout", action="store_true", help="also call Rollout (large, then 5 particles)")
    ap.add_argument("--steps", type=int, default=100, help="steps of the Rollout calls")
    ap.add_argument("--oversized", type=int, default=0,
                    help="then publish one state of this many particles (above the node's max_particles) "
                         "and report the node's diagnostics")
    ap.add_argument("--timeout", type=float, default=20.0, help="bound of each wait, seconds")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--contacts", action="store_true",
                    help="states are triangular packings touching within radius 1 (serve a model trained "
                         "with --radius 1) instead of spring rings")
    a = ap.parse_args()

    rclpy.init()
    node = rclpy.create_node("mcgnode_bench_large")
    arrived = {}
    sizes = {}

    def on_traj(data):
        sec, nsec = struct.unpack_from("<iI", data, 4)
        k = sec * NS + nsec
        arrived[k] = time.perf_counter()
        sizes[k] = len(data)

    # rclpy's defaults: reliable, volatile, keep-last 10.
    pub = node.create_publisher(ParticleState, "/particle_state", 10)
    diags = []
    node.create_subscription(NodeDiagnostics, "/mcgnode/diagnostics", diags.append, 10)
    node.create_subscription(PredictedTrajectory, "/mcgnode/predicted_trajectory", on_traj, 10, raw=True)
    # Created first: the node's reply writer must have matched the client's
    # reader before the first call, or the reply (volatile) is lost.
    client = node.create_client(Rollout, "/mcgnode/rollout")
    if not ru.spin_until(rclpy, node, lambda: pub.get_subscription_count() > 0
                         and node.count_publishers("/mcgnode/predicted_trajectory") > 0, a.timeout):
        print("FAIL: the node's endpoints never matched", flush=True)
        return 1
    time.sleep(1.0)  # let both directions of the match settle
    rng = random.Random(a.seed)
    shape = packing if a.contacts else ring
    big, small = shape(rng, a.particles), shape(rng, 5)
    stamp = [1_800_000_000 * NS]

    def send(m, timeout=None):
        stamp[0] += 1_000_000
        m.header.stamp = Time(sec=stamp[0] // NS, nanosec=stamp[0] % NS)
        k = stamp[0]
        t0 = time.perf_counter()
        pub.publish(m)
        # A blocking wait (spin_until's default step, ru.WAIT_STEP):
        # spin_once returns as soon as the trajectory's
        # callback (which stamps the arrival) has run. Polling every 1 ms
        # kept this process busy on a core the node's two rollout threads
        # need (the node's 100 steps took 57 ms instead of 42 on a 2-core
        # machine): that measured the bench, not the node.
        ok = ru.spin_until(rclpy, node, lambda: k in arrived, timeout or a.timeout)
        return k, (arrived[k] - t0) * 1000 if ok else None

    large_ms, small_ms, lost, big_bytes = [], [], 0, 0
    cpu0, wall0 = time.process_time(), time.perf_counter()
    # One unmeasured round: the first large message sizes Fast DDS's pools.
    for i in range(a.messages + 1):
        k, ms = send(big)
        if ms is None:
            lost += 1
            ms = a.timeout * 1000
        else:
            big_bytes = sizes[k]
        if i > 0:
            large_ms.append(ms)
        for _ in range(a.small):
            _, ms = send(small)
            if ms is None:
                lost += 1
                ms = a.timeout * 1000
            if i > 0:
                small_ms.append(ms)
    result = {"particles": a.particles, "contacts": a.contacts, "prediction_bytes": big_bytes,
              "large": summary(large_ms),
              "small_after_large": summary(small_ms), "lost": lost,
              # This process's CPU time over the measured loop, as a share of
              # its wall time: what the bench took from the node's cores.
              "bench_cpu_share": round((time.process_time() - cpu0)
                                       / max(time.perf_counter() - wall0, 1e-9), 3)}

    if a.rollout:
        if not client.wait_for_service(timeout_sec=a.timeout):
            print("FAIL: Rollout service not available", flush=True)
            return 1
        calls = {}
        for name, m in (("rollout_large", big), ("rollout_small_after", small)):
            req = Rollout.Request(initial=m, steps=a.steps, dt=0.0)
            t0 = time.perf_counter()
            fut = client.call_async(req)
            rclpy.spin_until_future_complete(node, fut, timeout_sec=a.timeout)
            ok = fut.done()
            ms = (time.perf_counter() - t0) * 1000
            r = fut.result() if ok else None
            calls[name] = {"answered": bool(ok), "ms": round(ms, 1),
                           "success": bool(r and r.success), "states": r.trajectory.steps if r else 0,
                           "message": r.message if r else ""}
        result.update(calls)

    if a.oversized:
        _, ms = send(ring(rng, a.oversized), timeout=2.0)  # refused: no prediction expected
        n = len(diags)
        _, small_ms_after = send(small)
        ru.spin_until(rclpy, node, lambda: len(diags) > n + 1, a.timeout)
        d = diags[-1] if diags else None
        result["oversized"] = {"predicted": ms is not None, "small_after_ms": small_ms_after,
                               "rejected": d.rejected if d else None,
                               "last_error": d.last_error if d else ""}

    print(f"{a.particles} particles ({big_bytes / 1e6:.2f} MB per prediction): "
          f"{json.dumps(result['large'])}; 5 particles right after: {json.dumps(result['small_after_large'])}; "
          f"lost {lost}; this bench's CPU share {result['bench_cpu_share']}", flush=True)
    print("LARGE_JSON " + json.dumps(result), flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0 if (large_ms and lost < a.messages * (1 + a.small)) else 1


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:
        sys.exit(130)
