#!/usr/bin/env python3
"""Drives a running `mcgnode serve` through the Plan action with real rclpy.
Run by tests/ros_plan.rs inside scripts/netns.sh. Every wait is bounded;
exits 1 with "FAIL: ..." on the first failed check; on success prints
`PLAN_ACTION_SUMMARY {json}`.

Checks:
  * a goal (the JSON Plan request given) gets one feedback per round of the
    search, numbered 1..iterations, whose best cost never rises and ends at
    the result's cost; the result succeeds (status SUCCEEDED);
  * a long goal (100 rounds) cancelled after its first feedback ends CANCELED
    well before its last round, with the best sequence found so far.
"""

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "ros"))
import _rosutil as ru  # noqa: E402

rclpy = ru.require_rclpy()
from rclpy.action import ActionClient  # noqa: E402

from mcgnode_msgs.action import Plan as PlanAction  # noqa: E402

SUCCEEDED, CANCELED = 4, 5


class Fail(Exception):
    pass


def check(cond, what):
    if not cond:
        raise Fail(what)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--goal", required=True, help="JSON of a Plan request")
    ap.add_argument("--action", default="/mcgnode/plan_action")
    ap.add_argument("--timeout", type=float, default=60)
    a = ap.parse_args()
    rclpy.init()
    node = rclpy.create_node("plan_drive")
    client = ActionClient(node, PlanAction, a.action)

    def wait(pred, timeout, what):
        check(ru.spin_until(rclpy, node, pred, timeout), f"timed out waiting for {what}")

    def send(data, feedback):
        fut = client.send_goal_async(ru.fill(PlanAction.Goal(), data),
                                     feedback_callback=lambda m: feedback.append(m.feedback))
        wait(fut.done, 10, "the goal response")
        h = fut.result()
        check(h.accepted, "goal rejected")
        return h

    def result(h):
        fut = h.get_result_async()
        wait(fut.done, a.timeout, "the action result")
        return fut.result()

    summary = {}
    try:
        check(client.wait_for_server(timeout_sec=20), f"action {a.action} not available")
        data = json.load(open(a.goal))
        # 1. A whole goal.
        fb = []
        t0 = time.monotonic()
        res = result(send(data, fb))
        check(res.status == SUCCEEDED and res.result.success,
              f"goal ended with status {res.status}: {res.result.message!r}")
        rounds = [f.iteration for f in fb]
        check(rounds == list(range(1, data["iterations"] + 1)), f"feedback rounds {rounds}")
        check(all(f.iterations == data["iterations"] for f in fb), "feedback's round count")
        best = [f.best_cost for f in fb]
        check(all(b2 <= b1 for b1, b2 in zip(best, best[1:])), f"best cost rose: {best}")
        check(best[-1] == res.result.cost, f"last feedback {best[-1]} vs result {res.result.cost}")
        summary.update(seconds=round(time.monotonic() - t0, 3), feedback=len(fb),
                       result=ru.to_plain(res.result))
        # 2. A long goal, cancelled after its first round.
        long = dict(data, iterations=100, candidates=1024)
        fb2 = []
        h = send(long, fb2)
        wait(lambda: len(fb2) >= 1, a.timeout, "the first feedback")
        t1 = time.monotonic()
        cf = h.cancel_goal_async()
        wait(cf.done, 10, "the cancel response")
        check(len(cf.result().goals_canceling) == 1, "cancel not accepted")
        res2 = result(h)
        check(res2.status == CANCELED, f"cancelled goal ended with status {res2.status}")
        check(res2.result.success and len(res2.result.best) == len(res.result.best),
              f"a cancelled plan keeps its best so far: {res2.result.message!r}")
        check(len(fb2) < 100, f"{len(fb2)} rounds ran after a cancel")
        summary.update(cancel_to_result_s=round(time.monotonic() - t1, 3), cancelled_after=len(fb2))
    except Fail as e:
        print(f"FAIL: {e}", flush=True)
        return 1
    finally:
        node.destroy_node()
        rclpy.shutdown()
    print("PLAN_ACTION_SUMMARY " + json.dumps(summary), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
