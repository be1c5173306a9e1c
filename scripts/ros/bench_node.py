#!/usr/bin/env python3
"""Latency and throughput of a running `mcgnode serve`, measured from rclpy.

Run by scripts/ros_bench.sh inside scripts/netns.sh next to the node. Two phases:

  (a) latency: publish a 5-particle spring state, wait for the node's
      PredictedTrajectory with the same header stamp, then send the next
      (one message in flight, so no queueing): p50/p99/max over --messages.
      The trajectory is taken raw (CDR bytes; only the stamp is decoded), so
      Python's message conversion is not part of the figure.
  (b) throughput: publish at --rate Hz for --duration s and compare the node's
      NodeDiagnostics counters (received, predicted) with what was sent; the
      forces topic is counted raw as what actually reached a subscriber. The
      node's resident memory (VmRSS from /proc/<pid>/status) is sampled once a
      second from start to end.

Prints a human-readable report and one line `BENCH_JSON {...}`. Every wait is
bounded; exits 1 with "FAIL: ..." if the node does not answer.
"""

import argparse
import json
import math
import os
import random
import statistics
import struct
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _rosutil as ru  # noqa: E402

rclpy = ru.require_rclpy()
from rclpy.executors import ExternalShutdownException  # noqa: E402

from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import Vector3  # noqa: E402
from mcgnode_msgs.msg import NodeDiagnostics, ParticleForces, ParticleState, PredictedTrajectory  # noqa: E402

NS = 1_000_000_000


class Fail(Exception):
    pass


def spring_state(rng, n=5):
    """A ring of n unit masses on unit springs, perturbed (as the training data)."""
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


def raw_stamp_ns(data):
    """Header stamp of a raw CDR message (after the 4-byte encapsulation header)."""
    sec, nsec = struct.unpack_from("<iI", data, 4)
    return sec * NS + nsec


def vm_rss_kib(pid):
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
    raise Fail(f"no VmRSS in /proc/{pid}/status")


def percentile(xs, p):
    """Nearest-rank percentile."""
    s = sorted(xs)
    return s[min(len(s) - 1, max(0, math.ceil(p / 100 * len(s)) - 1))]


class Bench:
    def __init__(self, a):
        self.a = a
        self.node = rclpy.create_node("mcgnode_bench")
        qos = ru.qos_profile(True, a.qos_depth)
        self.pub = self.node.create_publisher(ParticleState, a.input_topic, qos)
        self.arrived = {}  # stamp ns -> perf_counter at receipt
        self.forces_seen = 0
        self.diags = []
        self.subs = [
            self.node.create_subscription(PredictedTrajectory, a.trajectory_topic, self.on_traj, qos, raw=True),
            self.node.create_subscription(ParticleForces, a.forces_topic, self.on_forces, qos, raw=True),
            self.node.create_subscription(NodeDiagnostics, a.diagnostics_topic, self.diags.append,
                                          ru.qos_profile(True, 10)),
        ]
        self.rng = random.Random(a.seed)
        self.stamp = 1_800_000_000 * NS

    def on_traj(self, data):
        self.arrived[raw_stamp_ns(data)] = time.perf_counter()

    def on_forces(self, _data):
        self.forces_seen += 1

    def wait(self, pred, timeout, what, step=0.01):
        if not ru.spin_until(rclpy, self.node, pred, timeout, step=step):
            raise Fail(f"timed out after {timeout} s waiting for {what}")

    def next_state(self, template):
        # A distinct stamp per message: 1 ms apart, as a 1 kHz sensor would stamp.
        self.stamp += 1_000_000
        template.header.stamp = Time(sec=self.stamp // NS, nanosec=self.stamp % NS)
        return self.stamp

    def fresh_diag(self, timeout):
        """The first diagnostics message published after now."""
        n = len(self.diags)
        self.wait(lambda: len(self.diags) > n, timeout, "a NodeDiagnostics message")
        return self.diags[-1]

    def latency(self):
        a = self.a
        states = [spring_state(self.rng) for _ in range(16)]
        rss0 = vm_rss_kib(a.node_pid)
        lat = []
        for i in range(a.warmup + a.messages):
            m = states[i % len(states)]
            k = self.next_state(m)
            t0 = time.perf_counter()
            self.pub.publish(m)
            self.wait(lambda: k in self.arrived, a.timeout, f"the prediction of message {i}", step=0.001)
            if i >= a.warmup:
                lat.append(self.arrived[k] - t0)
        ms = [1000 * x for x in lat]
        return {
            "messages": len(ms),
            "p50_ms": round(percentile(ms, 50), 3),
            "p90_ms": round(percentile(ms, 90), 3),
            "p99_ms": round(percentile(ms, 99), 3),
            "max_ms": round(max(ms), 3),
            "mean_ms": round(statistics.fmean(ms), 3),
            "rss_kib_start": rss0,
            "rss_kib_end": vm_rss_kib(a.node_pid),
        }

    def throughput(self):
        a = self.a
        if not a.keep_trajectory_subscriber:
            # 1,000 trajectories of ~50 KB a second would load this 2-core
            # machine's Fast DDS receive threads, not the node: drop the reader.
            self.node.destroy_subscription(self.subs[0])
            self.subs = self.subs[1:]
        before = self.fresh_diag(a.timeout)
        forces_before = self.forces_seen
        rss = [(0.0, vm_rss_kib(a.node_pid))]
        states = [spring_state(self.rng) for _ in range(16)]
        period = 1.0 / a.rate
        total = int(round(a.rate * a.duration))
        sent = 0
        late = 0  # sends more than one period behind schedule
        t0 = time.perf_counter()
        next_rss = t0 + 1.0
        while sent < total:
            now = time.perf_counter()
            due = t0 + sent * period
            if now >= due:
                if now - due > period:
                    late += 1
                m = states[sent % len(states)]
                self.next_state(m)
                self.pub.publish(m)
                sent += 1
            else:
                # Handle incoming samples while waiting; never sleep past the deadline.
                rclpy.spin_once(self.node, timeout_sec=max(0.0, min(due - now, 0.0005)))
            if now >= next_rss:
                rss.append((round(now - t0, 1), vm_rss_kib(a.node_pid)))
                next_rss += 1.0
        send_s = time.perf_counter() - t0
        # Let the node drain, then read counters published after that.
        self.wait(lambda: time.perf_counter() - t0 > send_s + a.drain, a.drain + 5, "the drain period")
        after = self.fresh_diag(a.timeout)
        rss.append((round(time.perf_counter() - t0, 1), vm_rss_kib(a.node_pid)))
        received = after.received - before.received
        predicted = after.predicted - before.predicted
        rejected = after.rejected - before.rejected
        return {
            "rate_hz": a.rate,
            "duration_s": a.duration,
            "sent": sent,
            "achieved_send_rate_hz": round(sent / send_s, 1),
            "late_sends": late,
            "node_received": received,
            "node_predicted": predicted,
            "node_rejected": rejected,
            "dropped_before_node": sent - received,
            "received_not_predicted": received - predicted,
            "forces_delivered": self.forces_seen - forces_before,
            "trajectory_subscriber": a.keep_trajectory_subscriber,
            "rss_kib_start": rss[0][1],
            "rss_kib_end": rss[-1][1],
            "rss_kib_max": max(r for _, r in rss),
            "rss_samples": rss,
        }

    def run(self):
        a = self.a
        t = time.monotonic()
        self.wait(lambda: self.pub.get_subscription_count() >= 1, a.timeout, "the node's input subscription")
        self.wait(lambda: all(s.get_publisher_count() >= 1 for s in self.subs), a.timeout,
                  "the node's publishers")
        discovery = time.monotonic() - t
        out = {"discovery_s": round(discovery, 2), "node_pid": a.node_pid}
        if a.messages > 0:
            out["latency"] = self.latency()
        if a.duration > 0:
            out["throughput"] = self.throughput()
        out["model"] = self.diags[-1].model if self.diags else ""
        return out


def report(r):
    print(f"model: {r['model']}")
    if "latency" in r:
        lt = r["latency"]
        print(f"(a) latency, publish -> 100-step prediction received, {lt['messages']} messages one at a time:")
        print(f"    p50 {lt['p50_ms']} ms   p90 {lt['p90_ms']} ms   p99 {lt['p99_ms']} ms   "
              f"max {lt['max_ms']} ms   mean {lt['mean_ms']} ms")
        print(f"    node VmRSS: {lt['rss_kib_start']} KiB before, {lt['rss_kib_end']} KiB after")
    if "throughput" in r:
        th = r["throughput"]
        print(f"(b) sustained {th['rate_hz']} Hz for {th['duration_s']} s: sent {th['sent']} "
              f"(achieved {th['achieved_send_rate_hz']} Hz, {th['late_sends']} sends > 1 period late)")
        print(f"    node received {th['node_received']}, predicted {th['node_predicted']}, "
              f"rejected {th['node_rejected']}; dropped before the node {th['dropped_before_node']}, "
              f"received but not predicted {th['received_not_predicted']}; "
              f"forces delivered to rclpy {th['forces_delivered']}")
        print(f"    node VmRSS: start {th['rss_kib_start']} KiB, end {th['rss_kib_end']} KiB, "
              f"max {th['rss_kib_max']} KiB")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--node-pid", type=int, required=True, help="pid of the node (for VmRSS)")
    ap.add_argument("--messages", type=int, default=1000, help="latency samples (0: skip phase a)")
    ap.add_argument("--warmup", type=int, default=20, help="unmeasured messages first")
    ap.add_argument("--rate", type=float, default=1000.0, help="phase b publish rate, Hz")
    ap.add_argument("--duration", type=float, default=60.0, help="phase b seconds (0: skip)")
    ap.add_argument("--drain", type=float, default=2.0, help="seconds to let the node catch up")
    ap.add_argument("--keep-trajectory-subscriber", action="store_true",
                    help="keep subscribing to the trajectories during phase b")
    ap.add_argument("--qos-depth", type=int, default=10, help="keep-last depth of our endpoints")
    ap.add_argument("--timeout", type=float, default=20.0, help="bound of each wait, seconds")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--input-topic", default="/particle_state")
    ap.add_argument("--trajectory-topic", default="/mcgnode/predicted_trajectory")
    ap.add_argument("--forces-topic", default="/mcgnode/predicted_forces")
    ap.add_argument("--diagnostics-topic", default="/mcgnode/diagnostics")
    a = ap.parse_args()
    rclpy.init()
    code = 0
    try:
        r = Bench(a).run()
        report(r)
        print("BENCH_JSON " + json.dumps(r), flush=True)
    except Fail as e:
        print(f"FAIL: {e}", flush=True)
        code = 1
    except (KeyboardInterrupt, ExternalShutdownException):
        print("FAIL: interrupted", flush=True)
        code = 1
    finally:
        rclpy.try_shutdown()
    sys.exit(code)


if __name__ == "__main__":
    main()
