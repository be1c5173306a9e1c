#!/usr/bin/env python3
"""Drives a running `mcgnode serve` with real rclpy and checks what it answers.

Run by tests/ros_node.rs inside scripts/netns.sh next to the node (serving
truth:spring). Every wait is bounded. Exits 1 with "FAIL: ..." on the first
failed check; on success prints one line `DRIVE_SUMMARY {json}` with counts
and latencies.

Checks:
  * predictions (trajectory + forces) arrive for each published state, with the
    input's header, `horizon` states stamped k*dt later, and physics that holds
    (spring: momentum conserved; pendulum: bar lengths kept);
  * the Rollout service returns the same states as the topic for the same input,
    and refuses too many steps and malformed states;
  * MarkerArrays (rate-limited by markers_period) draw a predicted input:
    particles at its positions, one line per edge, paths ending at the
    predicted last state, force arrows along the predicted total forces;
  * malformed states (wrong lengths, NaN, out-of-range edge, bad dimension) are
    rejected, counted in NodeDiagnostics and warned about on /rosout, and the
    node keeps answering afterwards.
"""

import argparse
import json
import math
import os
import random
import statistics
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "ros"))
import _rosutil as ru  # noqa: E402

rclpy = ru.require_rclpy()
from rclpy.executors import ExternalShutdownException  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402

from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import Point, Vector3  # noqa: E402
from mcgnode_msgs.msg import NodeDiagnostics, ParticleForces, ParticleState, PredictedTrajectory  # noqa: E402
from mcgnode_msgs.srv import Rollout  # noqa: E402
from rcl_interfaces.msg import Log  # noqa: E402
from rcl_interfaces.srv import GetParameters  # noqa: E402
from visualization_msgs.msg import Marker, MarkerArray  # noqa: E402

NS = 1_000_000_000


class Fail(Exception):
    pass


def check(cond, what):
    if not cond:
        raise Fail(what)


def stamp_ns(t):
    return t.sec * NS + t.nanosec


def spring_state(rng, n, stamp):
    """A ring of n unit-mass particles joined by unit springs, perturbed."""
    radius = 0.5 / math.sin(math.pi / n)
    m = ParticleState()
    m.header.stamp = stamp
    m.header.frame_id = "lab"
    m.trajectory_id = 7
    m.step = 3
    m.system = "spring"
    m.dimension = 2
    m.types = [0] * n
    m.masses = [1.0] * n
    m.positions = [
        Vector3(x=radius * math.cos(2 * math.pi * i / n) + rng.uniform(-0.1, 0.1),
                y=radius * math.sin(2 * math.pi * i / n) + rng.uniform(-0.1, 0.1), z=0.0)
        for i in range(n)
    ]
    m.velocities = [Vector3(x=rng.uniform(-0.5, 0.5), y=rng.uniform(-0.5, 0.5), z=0.0) for _ in range(n)]
    m.edge_a = list(range(n))
    m.edge_b = [(i + 1) % n for i in range(n)]
    m.edge_kind = [ParticleState.EDGE_SPRING] * n
    m.edge_rest_length = [1.0] * n
    m.edge_stiffness = [1.0] * n
    return m


def pendulum_state(rng, n, stamp):
    """A chain of n unit bars hanging from an anchor at the origin, swinging
    (velocities consistent with the bars: each link turns at its own rate)."""
    m = ParticleState()
    m.header.stamp = stamp
    m.header.frame_id = "lab"
    m.system = "pendulum"
    m.dimension = 2
    m.types = [0] * n
    m.masses = [1.0] * n
    x = y = vx = vy = 0.0
    m.positions, m.velocities = [], []
    for _ in range(n):
        th, om = rng.uniform(-1.0, 1.0), rng.uniform(-1.0, 1.0)
        x, y = x + math.sin(th), y - math.cos(th)
        vx, vy = vx + om * math.cos(th), vy + om * math.sin(th)
        m.positions.append(Vector3(x=x, y=y, z=0.0))
        m.velocities.append(Vector3(x=vx, y=vy, z=0.0))
    m.edge_a = list(range(n))
    m.edge_b = [n] + list(range(n - 1))  # particle 0 to anchor 0 (index n), then i to i-1
    m.edge_kind = [ParticleState.EDGE_BAR] * n
    m.edge_rest_length = [1.0] * n
    m.edge_stiffness = [0.0] * n
    m.anchors = [Point(x=0.0, y=0.0, z=0.0)]
    return m


def momentum(state):
    return (sum(mm * v.x for mm, v in zip(state.masses, state.velocities)),
            sum(mm * v.y for mm, v in zip(state.masses, state.velocities)))


def bar_lengths(state):
    out = []
    n = len(state.types)
    for a, b in zip(state.edge_a, state.edge_b):
        pa = state.positions[a]
        pb = state.anchors[b - n] if b >= n else state.positions[b]
        out.append(math.hypot(pa.x - pb.x, pa.y - pb.y))
    return out


def plain_vecs(vs):
    return [(v.x, v.y, v.z) for v in vs]


class Driver:
    def __init__(self, args):
        self.args = args
        self.node = rclpy.create_node("mcgnode_driver")
        qos = ru.qos_profile(True, 50)
        self.pub = self.node.create_publisher(ParticleState, args.input_topic, ru.qos_profile(True, 50))
        self.trajs, self.forces, self.diags, self.logs = {}, {}, [], []
        self.recv_time = {}
        self.subs = [
            self.node.create_subscription(PredictedTrajectory, args.trajectory_topic, self.on_traj, qos),
            self.node.create_subscription(ParticleForces, args.forces_topic, self.on_forces, qos),
            self.node.create_subscription(NodeDiagnostics, args.diagnostics_topic, self.diags.append, qos),
        ]
        self.node.create_subscription(Log, "/rosout", self.logs.append, ru.qos_profile(True, 1000))
        self.markers = []
        self.node.create_subscription(MarkerArray, "/mcgnode/markers", self.markers.append, qos)
        self.client = self.node.create_client(Rollout, args.rollout_service)
        self.sent = {}  # stamp ns -> (state, monotonic send time)

    def on_traj(self, msg):
        k = stamp_ns(msg.header.stamp)
        self.trajs[k] = msg
        self.recv_time.setdefault(k, time.monotonic())

    def on_forces(self, msg):
        self.forces[stamp_ns(msg.header.stamp)] = msg

    def wait(self, pred, timeout, what):
        if not ru.spin_until(rclpy, self.node, pred, timeout, step=0.01):
            raise Fail(f"timed out after {timeout} s waiting for {what}")

    def publish(self, state):
        self.sent[stamp_ns(state.header.stamp)] = (state, time.monotonic())
        self.pub.publish(state)

    def call(self, request, timeout):
        t0 = time.monotonic()
        fut = self.client.call_async(request)
        rclpy.spin_until_future_complete(self.node, fut, timeout_sec=timeout)
        check(fut.done(), f"no Rollout response within {timeout} s")
        return fut.result(), time.monotonic() - t0

    def check_prediction(self, k):
        state, _ = self.sent[k]
        traj, forces = self.trajs[k], self.forces[k]
        a = self.args
        check(traj.header == state.header, f"trajectory header {traj.header} != input {state.header}")
        check(forces.header == state.header, "forces header differs from the input's")
        states = ru.predicted_states(traj)
        check(traj.steps == a.horizon and len(states) == a.horizon,
              f"{traj.steps} predicted states, horizon is {a.horizon}")
        n, d = len(state.positions), state.dimension
        check(len(traj.spread) == 0, "a single model's prediction has no spread")
        check(len(traj.positions) == len(traj.velocities) == a.horizon * n * d,
              f"{len(traj.positions)} coordinates for {a.horizon} states of {n} particles in {d}D")
        check(abs(traj.dt - a.dt) < 1e-15, f"trajectory dt {traj.dt} != {a.dt}")
        check(plain_vecs(traj.initial.positions) == plain_vecs(state.positions), "initial state altered")
        for i, s in enumerate(states):
            want = k + round((i + 1) * a.dt * NS)
            check(s.stamp_ns == want, f"state {i} at {s.stamp_ns}, want {want}")
            check(s.step == state.step + i + 1, f"state {i} has step {s.step}")
        last = states[-1]
        check(plain_vecs(last.positions) != plain_vecs(state.positions), "the prediction did not move")
        n = len(state.types)
        check(len(forces.total) == n, f"{len(forces.total)} total forces for {n} particles")
        if state.system == "spring":
            p0, p1 = momentum(state), momentum(last)
            check(all(abs(x - y) < 1e-9 for x, y in zip(p0, p1)), f"momentum {p0} -> {p1} (springs conserve it)")
            check(len(forces.edge_force) == n, f"{len(forces.edge_force)} pairwise forces for a {n}-ring")
            fx = sum(f.x for f in forces.total)
            check(abs(fx) < 1e-9, f"internal forces sum to {fx}, not 0")
        else:
            err = max(abs(L - 1.0) for L in bar_lengths(last))
            check(err < 1e-6, f"bar lengths drift by {err} (rigid bars)")

    def check_markers(self, arr):
        """One MarkerArray against the input and prediction it draws."""
        ms = arr.markers
        check(ms and ms[0].action == Marker.DELETEALL, "a MarkerArray does not start with DELETEALL")
        by_ns = {}
        for m in ms[1:]:
            by_ns.setdefault(m.ns, []).append(m)
        (parts,) = by_ns["particles"]
        k = stamp_ns(parts.header.stamp)
        check(k in self.sent and k in self.trajs, f"markers stamped {k} match no predicted input")
        state, traj, forces = self.sent[k][0], self.trajs[k], self.forces[k]
        check(parts.type == Marker.SPHERE_LIST, f"particles drawn as type {parts.type}")
        check(plain_vecs(parts.points) == plain_vecs(state.positions), "particles not at the input's positions")
        (edges,) = by_ns["edges"]
        check(len(edges.points) == 2 * len(state.edge_a), f"{len(edges.points)} edge points, {len(state.edge_a)} edges")
        (paths,) = by_ns["predicted_paths"]
        n = len(state.positions)
        check(len(paths.points) == 2 * n * traj.steps, "one path segment per particle and step")
        check(plain_vecs(paths.points[1::2][-n:]) == plain_vecs(ru.predicted_states(traj)[-1].positions),
              "paths do not end at the predicted last state")
        arrows = by_ns.get("forces", [])
        check(len(arrows) == n and all(m.type == Marker.ARROW for m in arrows), "one force arrow per particle")
        for m, p, f in zip(sorted(arrows, key=lambda m: m.id), state.positions, forces.total):
            d = (m.points[1].x - p.x, m.points[1].y - p.y, m.points[1].z - p.z)
            cross = (d[1] * f.z - d[2] * f.y, d[2] * f.x - d[0] * f.z, d[0] * f.y - d[1] * f.x)
            scale = math.hypot(*d) * math.hypot(f.x, f.y, f.z)
            check(max(map(abs, cross)) <= 1e-9 * max(scale, 1e-300), "a force arrow is not along its force")
            check(d[0] * f.x + d[1] * f.y + d[2] * f.z >= 0, "a force arrow points against its force")

    def run(self):
        a = self.args
        rng = random.Random(a.seed)
        t_start = time.monotonic()
        # Discovery: the node subscribes to our input, publishes what we read.
        self.wait(lambda: self.pub.get_subscription_count() >= 1, a.timeout, "the node's input subscription")
        self.wait(lambda: all(s.get_publisher_count() >= 1 for s in self.subs),
                  a.timeout, "the node's publishers to match our subscriptions")
        check(self.client.wait_for_service(timeout_sec=a.timeout), "Rollout service not available")
        discovery_s = time.monotonic() - t_start

        # Valid states: springs and pendulums, each with a distinct stamp. The
        # first also completes matching and is left out of the latency figures.
        base = 1_700_000_000
        valid = []
        for i in range(a.states + 1):
            stamp = Time(sec=base + i, nanosec=123_000_000 + i)
            st = spring_state(rng, 5, stamp) if i % 2 == 0 else pendulum_state(rng, 3, stamp)
            valid.append(stamp_ns(stamp))
            self.publish(st)
            # One at a time, so latencies are not queueing delays.
            self.wait(lambda k=stamp_ns(stamp): k in self.trajs and k in self.forces, a.timeout,
                      f"the prediction for state {i}")
        for k in valid:
            self.check_prediction(k)
        self.wait(lambda: len(self.markers) >= 1, a.timeout, "a MarkerArray")
        for arr in self.markers:
            self.check_markers(arr)
        latencies = [self.recv_time[k] - self.sent[k][1] for k in valid]
        first_prediction_s, latencies = latencies[0], latencies[1:]

        # Rollout: same input, same answer as the topic; bounded steps; checks input.
        first = self.sent[valid[0]][0]
        req = Rollout.Request(initial=first, steps=a.horizon, dt=0.0)
        resp, first_call_s = self.call(req, a.timeout)
        check(resp.success, f"Rollout failed: {resp.message}")
        got = list(resp.trajectory.positions)
        want = list(self.trajs[valid[0]].positions)
        check(got == want, "Rollout and the topic disagree for the same input")
        call_s = []
        for _ in range(a.calls):
            resp, took = self.call(Rollout.Request(initial=first, steps=a.horizon, dt=0.002), a.timeout)
            check(resp.success and resp.trajectory.steps == a.horizon, f"Rollout: {resp.message}")
            call_s.append(took)
        resp, _ = self.call(Rollout.Request(initial=first, steps=a.max_rollout_steps + 1), a.timeout)
        check(not resp.success and "max_rollout_steps" in resp.message, f"too many steps accepted: {resp.message}")
        bad = spring_state(rng, 5, Time(sec=base, nanosec=1))
        bad.masses = bad.masses[:-1]
        resp, _ = self.call(Rollout.Request(initial=bad, steps=5), a.timeout)
        check(not resp.success and "malformed" in resp.message, f"malformed Rollout accepted: {resp.message}")

        # The parameters are visible to ROS tools (read through the parameter service).
        pclient = self.node.create_client(GetParameters, "/mcgnode/get_parameters")
        check(pclient.wait_for_service(timeout_sec=a.timeout), "no /mcgnode/get_parameters service")
        fut = pclient.call_async(GetParameters.Request(names=["horizon", "model", "dt"]))
        rclpy.spin_until_future_complete(self.node, fut, timeout_sec=a.timeout)
        check(fut.done(), "no get_parameters response")
        vals = fut.result().values
        check(len(vals) == 3 and vals[0].integer_value == a.horizon and vals[1].string_value == "truth:spring"
              and vals[2].double_value == a.dt, f"get_parameters gave {vals}")

        # Malformed inputs.
        malformed = []
        for i, how in enumerate(["short", "nan", "edge", "dim"]):
            m = spring_state(rng, 5, Time(sec=base + 1000 + i, nanosec=0))
            if how == "short":
                m.masses = m.masses[:-1]
            elif how == "nan":
                m.positions[2].x = float("nan")
            elif how == "edge":
                m.edge_b[1] = 99
            else:
                m.dimension = 5
            malformed.append(m)
        t_bad = time.monotonic()
        for m in malformed:
            self.publish(m)
        # Bytes that are not a ParticleState at all (a truncated serialization).
        raw = serialize_message(spring_state(rng, 5, Time(sec=base + 1500, nanosec=0)))
        self.pub.publish(raw[: len(raw) // 3])
        # After the warning period, one more: its warning reports the suppressed ones.
        self.wait(lambda: time.monotonic() - t_bad > a.warn_period + 0.3, a.warn_period + 5, "the warning period")
        late = spring_state(rng, 5, Time(sec=base + 2000, nanosec=0))
        late.velocities = late.velocities[:2]
        self.publish(late)
        n_bad = len(malformed) + 2

        # Still answering: a valid state after the bad ones, and a Rollout call.
        stamp = Time(sec=base + 3000, nanosec=5)
        self.publish(spring_state(rng, 5, stamp))
        self.wait(lambda: stamp_ns(stamp) in self.trajs and stamp_ns(stamp) in self.forces, a.timeout,
                  "a prediction after malformed input")
        self.check_prediction(stamp_ns(stamp))
        resp, _ = self.call(Rollout.Request(initial=first, steps=3), a.timeout)
        check(resp.success, f"Rollout after malformed input failed: {resp.message}")
        n_valid = len(valid) + 1

        def diag_ok():
            return any(d.rejected >= n_bad and d.received >= n_valid + n_bad and d.predicted >= n_valid
                       for d in self.diags)

        self.wait(diag_ok, a.timeout, f"diagnostics counting {n_bad} rejections (last seen: "
                  f"{self.diags[-1] if self.diags else 'none'})")
        d = [d for d in self.diags if d.rejected >= n_bad][-1]
        check(d.rejected == n_bad, f"diagnostics count {d.rejected} rejections, {n_bad} were sent")
        check(d.predicted == n_valid, f"diagnostics count {d.predicted} predictions, {n_valid} were made")
        check(d.last_error != "", "diagnostics have no last_error")
        check("truth:spring" in d.model, f"diagnostics model {d.model!r}")

        def warned():
            return [g for g in self.logs if g.name == "mcgnode" and g.level == 30 and "rejected input" in g.msg]

        self.wait(lambda: any("suppressed" in g.msg for g in warned()), a.timeout,
                  "a rate-limited warning on /rosout")
        check(len(warned()) < n_bad, f"{len(warned())} warnings for {n_bad} rejections: not rate-limited")

        summary = {
            "discovery_wait_s": round(discovery_s, 3),
            "predictions": n_valid,
            "rejected": d.rejected,
            "undecodable": 1,
            "rosout_warnings": len(warned()),
            "marker_arrays": len(self.markers),
            "first_prediction_ms": round(1000 * first_prediction_s, 2),
            "prediction_latency_ms": {
                "median": round(1000 * statistics.median(latencies), 2),
                "max": round(1000 * max(latencies), 2),
            },
            "first_rollout_call_ms": round(1000 * first_call_s, 2),
            "rollout_call_ms": {
                "median": round(1000 * statistics.median(call_s), 2),
                "max": round(1000 * max(call_s), 2),
                "calls": len(call_s),
                "steps": a.horizon,
            },
        }
        print("DRIVE_SUMMARY " + json.dumps(summary), flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--horizon", type=int, required=True)
    ap.add_argument("--dt", type=float, required=True)
    ap.add_argument("--max-rollout-steps", type=int, required=True)
    ap.add_argument("--warn-period", type=float, required=True)
    ap.add_argument("--states", type=int, default=6, help="valid states to publish")
    ap.add_argument("--calls", type=int, default=20, help="timed Rollout calls")
    ap.add_argument("--timeout", type=float, default=20.0, help="bound of each wait, seconds")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--input-topic", default="/particle_state")
    ap.add_argument("--trajectory-topic", default="/mcgnode/predicted_trajectory")
    ap.add_argument("--forces-topic", default="/mcgnode/predicted_forces")
    ap.add_argument("--diagnostics-topic", default="/mcgnode/diagnostics")
    ap.add_argument("--rollout-service", default="/mcgnode/rollout")
    args = ap.parse_args()
    rclpy.init()
    code = 0
    try:
        Driver(args).run()
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
