#!/usr/bin/env python3
"""Drives `mcgnode serve --set lifecycle=true` through the managed-node
lifecycle with rclpy's lifecycle_msgs services, as `ros2 lifecycle` does.

Run by tests/ros_node.rs inside scripts/netns.sh next to the node (serving
truth:spring). Every wait is bounded. Exits 1 with "FAIL: ..." on the first
failed check; on success prints `LIFECYCLE_SUMMARY {json}`.

Checks: the node starts unconfigured and predicts nothing, refuses Rollout and
an unavailable transition; configure (by label) and activate (by id) make it
predict, each announced on /mcgnode/transition_event; deactivate stops the
predictions again; the transition graph has rclcpp's seven primary transitions.
"""

import json
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "ros"))
import _rosutil as ru  # noqa: E402

rclpy = ru.require_rclpy()
from builtin_interfaces.msg import Time  # noqa: E402
from lifecycle_msgs.msg import State, Transition, TransitionEvent  # noqa: E402
from lifecycle_msgs.srv import ChangeState, GetAvailableTransitions, GetState  # noqa: E402
from mcgnode_msgs.msg import ParticleState, PredictedTrajectory  # noqa: E402
from mcgnode_msgs.srv import Rollout  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from drive import Fail, check, spring_state  # noqa: E402

TIMEOUT = 20.0


def main():
    import random

    rclpy.init()
    node = rclpy.create_node("lifecycle_driver")
    qos = ru.qos_profile(True, 50)
    pub = node.create_publisher(ParticleState, "/particle_state", qos)
    trajs, events = [], []
    node.create_subscription(PredictedTrajectory, "/mcgnode/predicted_trajectory", trajs.append, qos)
    node.create_subscription(TransitionEvent, "/mcgnode/transition_event", events.append, qos)
    clients = {
        "change": node.create_client(ChangeState, "/mcgnode/change_state"),
        "get": node.create_client(GetState, "/mcgnode/get_state"),
        "available": node.create_client(GetAvailableTransitions, "/mcgnode/get_available_transitions"),
        "graph": node.create_client(GetAvailableTransitions, "/mcgnode/get_transition_graph"),
        "rollout": node.create_client(Rollout, "/mcgnode/rollout"),
    }
    rng = random.Random(5)
    sent = [0]

    def call(name, req):
        fut = clients[name].call_async(req)
        rclpy.spin_until_future_complete(node, fut, timeout_sec=TIMEOUT)
        check(fut.done(), f"no {name} response within {TIMEOUT} s")
        return fut.result()

    def state():
        return call("get", GetState.Request()).current_state

    def change(tid=0, label=""):
        return call("change", ChangeState.Request(transition=Transition(id=tid, label=label))).success

    def publish():
        sent[0] += 1
        st = spring_state(rng, 5, Time(sec=1_700_000_000 + sent[0], nanosec=0))
        pub.publish(st)
        return st

    def predicts(within):
        before = len(trajs)
        publish()
        return ru.spin_until(rclpy, node, lambda: len(trajs) > before, within, step=0.01)

    try:
        for name, c in clients.items():
            check(c.wait_for_service(timeout_sec=TIMEOUT), f"{name} service not available")
        check(ru.spin_until(rclpy, node, lambda: pub.get_subscription_count() >= 1, TIMEOUT),
              "the node's input subscription")
        s = state()
        check((s.id, s.label) == (State.PRIMARY_STATE_UNCONFIGURED, "unconfigured"), f"starts {s}")
        check(not predicts(1.5), "an unconfigured node predicted")
        r = call("rollout", Rollout.Request(initial=publish(), steps=5, dt=0.0))
        check(not r.success and "unconfigured" in r.message, f"Rollout while unconfigured: {r.message}")
        check(not change(label="activate"), "activate accepted while unconfigured")
        labels = sorted(t.transition.label for t in call("available", GetAvailableTransitions.Request())
                        .available_transitions)
        check(labels == ["configure", "shutdown"], f"transitions from unconfigured: {labels}")
        check(change(label="configure"), "configure refused")
        check(state().id == State.PRIMARY_STATE_INACTIVE, "not inactive after configure")
        check(not predicts(1.0), "an inactive node predicted")
        check(change(tid=Transition.TRANSITION_ACTIVATE), "activate refused")
        check(state().label == "active", "not active after activate")
        check(predicts(TIMEOUT), "an active node did not predict")
        r = call("rollout", Rollout.Request(initial=publish(), steps=5, dt=0.0))
        check(r.success and r.trajectory.steps == 5, f"Rollout while active: {r.message}")
        check(change(label="deactivate"), "deactivate refused")
        check(not predicts(1.5), "a deactivated node predicted")
        check(ru.spin_until(rclpy, node, lambda: len(events) >= 3, TIMEOUT), f"{len(events)} transition events")
        seen = [(e.transition.label, e.start_state.label, e.goal_state.label) for e in events]
        want = [("configure", "unconfigured", "inactive"), ("activate", "inactive", "active"),
                ("deactivate", "active", "inactive")]
        check(seen == want, f"transition events {seen}")
        graph = call("graph", GetAvailableTransitions.Request()).available_transitions
        check(len(graph) == 7, f"{len(graph)} transitions in the graph")
    except Fail as e:
        print(f"FAIL: {e}", flush=True)
        sys.exit(1)
    print("LIFECYCLE_SUMMARY " + json.dumps({"events": len(events), "predictions": len(trajs)}), flush=True)
    node.destroy_node()
    rclpy.shutdown()


if __name__ == "__main__":
    main()
