#!/usr/bin/env python3
"""Drives three mcgnode nodes on one DDS domain (run by tests/ros_fleet.rs
inside scripts/netns.sh):

  robot1: `serve --model truth:spring --ros-args -r __ns:=/robot1 -p horizon:=20`
  robot2: the shipped MCGNODE, `-r __ns:=/robot2 -p horizon:=20`
  dyn3:   truth:spring, `-r __node:=dyn3 -r particle_state:=/tracker/state`

For each: publishes states on its input (/robot1/particle_state,
/robot2/particle_state, /tracker/state; a different number to each), collects
its predictions (/robot1/mcgnode/predicted_trajectory, ...,
/dyn3/predicted_trajectory), calls its Rollout, and (robot1, robot2) its Train
with a different epoch count, watching every node's model_swap topic. Exits 1
with `FAIL: ...` on the first failed check, else prints `FLEET_SUMMARY {json}`.
"""

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "ros"))
import _rosutil as ru  # noqa: E402

rclpy = ru.require_rclpy()
from rclpy.serialization import deserialize_message  # noqa: E402

from mcgnode_msgs.msg import ModelSwap, ParticleState, PredictedTrajectory  # noqa: E402
from mcgnode_msgs.srv import Rollout, Train  # noqa: E402

NODES = {
    "robot1": {"input": "/robot1/particle_state", "base": "/robot1/mcgnode", "sends": 3},
    "robot2": {"input": "/robot2/particle_state", "base": "/robot2/mcgnode", "sends": 5},
    "dyn3": {"input": "/tracker/state", "base": "/dyn3", "sends": 2},
}


class Fail(Exception):
    pass


def check(cond, what):
    if not cond:
        raise Fail(what)


def read_state(path):
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        for s, _c, m in make_reader(f).iter_messages(log_time_order=True):
            if s is not None and s.name == "mcgnode_msgs/msg/ParticleState":
                return deserialize_message(m.data, ParticleState)
    raise Fail(f"no ParticleState in {path}")


def last_positions(traj):
    n, d = len(traj.initial.masses), traj.initial.dimension
    last = traj.positions[len(traj.positions) - n * d:]
    return [(float(last[i]), float(last[i + 1])) for i in range(0, n * d, d)]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--state-bag", required=True)
    ap.add_argument("--train-bag", required=True)
    a = ap.parse_args()
    rclpy.init()
    node = rclpy.create_node("fleet_drive")
    qos = ru.qos_profile(True, 100)
    got = {k: [] for k in NODES}
    swaps = {k: [] for k in NODES}
    pubs, clients, trains, subs = {}, {}, {}, []
    for k, n in NODES.items():
        pubs[k] = node.create_publisher(ParticleState, n["input"], qos)
        subs.append(node.create_subscription(
            PredictedTrajectory, n["base"] + "/predicted_trajectory", lambda m, k=k: got[k].append(m), qos))
        subs.append(node.create_subscription(
            ModelSwap, n["base"] + "/model_swap", lambda m, k=k: swaps[k].append(m), qos))
        clients[k] = node.create_client(Rollout, n["base"] + "/rollout")
        trains[k] = node.create_client(Train, n["base"] + "/train")
    state = read_state(a.state_bag)
    summary = {}

    def spin_until(pred, timeout, what):
        if not ru.spin_until(rclpy, node, pred, timeout, step=0.01):
            raise Fail(f"timed out after {timeout} s waiting for {what}")

    def call(client, req, timeout):
        check(client.wait_for_service(timeout_sec=20), f"{client.srv_name} never appeared")
        fut = client.call_async(req)
        spin_until(fut.done, timeout, f"the answer of {client.srv_name}")
        return fut.result()

    try:
        spin_until(lambda: all(p.get_subscription_count() >= 1 for p in pubs.values())
                   and all(s.get_publisher_count() >= 1 for s in subs), 30,
                   "every node's input, predictions and swaps to match")
        # Which node listens where: exactly one subscriber per input.
        summary["input_subscribers"] = {k: pubs[k].get_subscription_count() for k in NODES}
        time.sleep(0.5)
        for k, n in NODES.items():
            for i in range(n["sends"]):
                state.trajectory_id = 100 + i
                pubs[k].publish(state)
        spin_until(lambda: all(len(got[k]) >= n["sends"] for k, n in NODES.items()), 20, "the predictions")
        # Anything crossing would arrive late: wait a little longer.
        ru.spin_until(rclpy, node, lambda: False, 1.0, step=0.02)
        summary["predictions"] = {k: len(v) for k, v in got.items()}
        for k, n in NODES.items():
            check(len(got[k]) == n["sends"], f"{k} got {len(got[k])} predictions for {n['sends']} states")
            check(all(t.steps == 20 for t in got[k]), f"{k}: horizon:=20 not applied")
        end = {k: last_positions(v[0]) for k, v in got.items()}
        diff = lambda x, y: max(abs(p - q) for a_, b_ in zip(end[x], end[y]) for p, q in zip(a_, b_))  # noqa: E731
        summary["truth_vs_truth"] = diff("robot1", "dyn3")
        summary["truth_vs_learned"] = diff("robot1", "robot2")
        check(summary["truth_vs_truth"] < 1e-12, "two truth servers disagree")
        check(summary["truth_vs_learned"] > 1e-9, "robot2 answered like the truth server")
        # Rollout: each answers with its own model.
        roll = {}
        for k in NODES:
            req = Rollout.Request()
            req.initial = state
            req.steps = 20
            res = call(clients[k], req, 20)
            check(res.success, f"{k} rollout: {res.message}")
            roll[k] = last_positions(res.trajectory)
        rd = lambda x, y: max(abs(p - q) for a_, b_ in zip(roll[x], roll[y]) for p, q in zip(a_, b_))  # noqa: E731
        check(rd("robot1", "dyn3") < 1e-12 and rd("robot1", "robot2") > 1e-9, "rollouts crossed")
        check(max(abs(p - q) for a_, b_ in zip(roll["robot2"], end["robot2"]) for p, q in zip(a_, b_)) < 1e-12,
              "robot2's rollout differs from its topic prediction")
        # Train: robot1 and robot2, different epochs; each swap only on its own topic.
        for k, epochs in (("robot1", 2), ("robot2", 3)):
            req = Train.Request()
            req.bags = [a.train_bag]
            req.epochs = epochs
            res = call(trains[k], req, 120)
            check(res.success, f"{k} train: {res.message}")
            summary[f"{k}_model"] = res.model_path
        spin_until(lambda: len(swaps["robot1"]) >= 1 and len(swaps["robot2"]) >= 1, 10, "the swaps")
        ru.spin_until(rclpy, node, lambda: False, 1.0, step=0.02)
        summary["swaps"] = {k: len(v) for k, v in swaps.items()}
        check(summary["swaps"] == {"robot1": 1, "robot2": 1, "dyn3": 0}, f"swaps {summary['swaps']}")
        check(swaps["robot1"][0].new_model != swaps["robot2"][0].new_model, "both swapped in one model")
    except Fail as e:
        print(f"FAIL: {e}", flush=True)
        print("FLEET_SUMMARY " + json.dumps(summary), flush=True)
        sys.exit(1)
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    print("FLEET_SUMMARY " + json.dumps(summary), flush=True)


if __name__ == "__main__":
    main()
