#!/usr/bin/env python3
"""Drives a running `mcgnode serve` (serving a trained model file) through
retraining and model swaps with real rclpy. Run by tests/ros_train.rs inside
scripts/netns.sh. Every wait is bounded; exits 1 with "FAIL: ..." on the first
failed check; on success prints `TRAIN_SUMMARY {json}`.

Checks:
  * Train service on a bag: predictions keep arriving while it trains, a second
    Train call and a second action goal are refused meanwhile, the swap is
    announced on /mcgnode/model_swap with the new model path, later predictions
    come from the new model (differ from the old ones, and equal what the saved
    file gives once loaded with LoadModel);
  * Train with a missing bag fails, says why, keeps the old model;
  * LoadModel with a missing or corrupt file fails and keeps the model; with a
    good file it swaps (announced) and predictions equal the file's;
  * the Train action: per-epoch feedback, a result, a swap; a cancelled goal
    ends CANCELED and leaves the model as it was;
  * Train with no bags trains on what the node recorded (a played trajectory);
  * Train with fine_tune continues the served model (weights, Adam state) and
    refuses another variant;
  * a training still running when the driver ends (the node must stop on SIGINT).
"""

import argparse
import json
import math
import os
import statistics
import sys
import time

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "scripts", "ros"))
import _rosutil as ru  # noqa: E402

rclpy = ru.require_rclpy()
from rclpy.action import ActionClient  # noqa: E402
from rclpy.serialization import deserialize_message  # noqa: E402

from mcgnode_msgs.action import Train as TrainAction  # noqa: E402
from mcgnode_msgs.msg import ModelSwap, ParticleState, PredictedTrajectory  # noqa: E402
from mcgnode_msgs.srv import LoadModel, Train  # noqa: E402

SUCCEEDED, CANCELED = 4, 5


class Fail(Exception):
    pass


def check(cond, what):
    if not cond:
        raise Fail(what)


def read_states(path):
    """Raw CDR of every ParticleState in a bag, in log-time order."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [
            m.data
            for s, _c, m in make_reader(f).iter_messages(log_time_order=True)
            if s is not None and s.name == "mcgnode_msgs/msg/ParticleState"
        ]


def positions(traj):
    return [float(x) for x in traj.positions]


def max_diff(a, b):
    check(len(a) == len(b), f"prediction sizes differ: {len(a)} vs {len(b)}")
    return max(abs(x - y) for x, y in zip(a, b))


class Driver:
    def __init__(self, args):
        self.a = args
        rclpy.init()
        self.node = rclpy.create_node("train_drive")
        qos = ru.qos_profile(True, 100)
        self.pub = self.node.create_publisher(ParticleState, "/particle_state", qos)
        self.preds = {}
        self.node.create_subscription(PredictedTrajectory, "/mcgnode/predicted_trajectory", self.on_pred, qos)
        self.swaps = []
        self.node.create_subscription(ModelSwap, "/mcgnode/model_swap", self.on_swap, qos)
        self.train = self.node.create_client(Train, "/mcgnode/train")
        self.load = self.node.create_client(LoadModel, "/mcgnode/load_model")
        self.action = ActionClient(self.node, TrainAction, "/mcgnode/train_action")
        self.base = read_states(args.state_bag)
        check(len(self.base) > 0, f"no states in {args.state_bag}")
        self.next_id = 1000
        self.sent = {}
        self.summary = {}

    def on_pred(self, msg):
        self.preds[msg.initial.trajectory_id] = (time.monotonic(), positions(msg))

    def on_swap(self, msg):
        self.swaps.append((time.monotonic(), msg))

    def spin_until(self, pred, timeout, what):
        if not ru.spin_until(rclpy, self.node, pred, timeout, step=0.01):
            raise Fail(f"timed out after {timeout} s waiting for {what}")

    def send_state(self):
        """Publishes the reference state under a fresh trajectory id (so the
        recording holds no repeated step); returns that id."""
        msg = deserialize_message(self.base[0], ParticleState)
        msg.trajectory_id = self.next_id
        msg.step = 0
        self.next_id += 1
        self.sent[msg.trajectory_id] = time.monotonic()
        self.pub.publish(msg)
        return msg.trajectory_id

    def predict(self):
        i = self.send_state()
        self.spin_until(lambda: i in self.preds, 10, f"the prediction for state {i}")
        return self.preds[i][1]

    def call(self, client, request, timeout, busy=None):
        """Calls a service; while waiting, `busy()` runs every 50 ms."""
        fut = client.call_async(request)
        last = 0.0
        deadline = time.monotonic() + timeout
        while not fut.done():
            check(time.monotonic() < deadline, f"no response from {client.srv_name} in {timeout} s")
            if busy is not None and time.monotonic() - last > 0.05:
                busy()
                last = time.monotonic()
            rclpy.spin_once(self.node, timeout_sec=0.01)
        return fut.result()

    def swap_with(self, text, since, timeout=5):
        self.spin_until(lambda: any(t >= since and text in m.reason for t, m in self.swaps), timeout,
                        f"a model swap announcing {text!r}")
        return [m for t, m in self.swaps if t >= since and text in m.reason][-1]

    def send_goal(self, goal, feedback):
        fut = self.action.send_goal_async(goal, feedback_callback=lambda m: feedback.append(m.feedback))
        self.spin_until(fut.done, 10, "the goal response")
        return fut.result()

    def result(self, handle, timeout):
        fut = handle.get_result_async()
        self.spin_until(fut.done, timeout, "the action result")
        return fut.result()

    def run(self):
        a = self.a
        for c in (self.train, self.load):
            check(c.wait_for_service(timeout_sec=20), f"service {c.srv_name} not available")
        check(self.action.wait_for_server(timeout_sec=20), "Train action not available")
        self.spin_until(lambda: self.pub.get_subscription_count() >= 1, 20, "the node's subscription")
        p_old = self.predict()
        idle = []
        for _ in range(20):
            check(self.predict() == p_old, "the same state gave two different predictions")
            idle.append(self.next_id - 1)

        # 1. Train service in the background; refusals meanwhile.
        during = []
        refusals = {}

        def busy():
            during.append(self.send_state())
            if len(during) == 3:
                r = self.call(self.train, Train.Request(bags=[a.train_bag], epochs=1), 10)
                refusals["service"] = (r.success, r.message)
                fb = []
                h = self.send_goal(TrainAction.Goal(bags=[a.train_bag], epochs=1), fb)
                refusals["action_accepted"] = h.accepted

        t0 = time.monotonic()
        r = self.call(self.train, Train.Request(bags=[a.train_bag], variant="mcgnode", epochs=a.epochs, seed=3),
                      120, busy)
        t_train = time.monotonic() - t0
        check(r.success, f"Train failed: {r.message}")
        check(os.path.isfile(r.model_path), f"model_path {r.model_path!r} is not a file")
        check(math.isfinite(r.train_loss) and math.isfinite(r.validation_loss) and r.validation_loss > 0,
              f"losses {r.train_loss}, {r.validation_loss}")
        check(math.isfinite(r.explained) and r.explained <= 1.0 and "explains" in r.message,
              f"explained fraction {r.explained} / message {r.message!r}")
        got = [i for i in during if i in self.preds and self.preds[i][0] <= t0 + t_train]
        check(len(got) >= 3, f"only {len(got)} of {len(during)} states were answered during training")
        check("service" in refusals, "training ended before a second request could be sent; raise --epochs")
        check(not refusals["service"][0] and "already running" in refusals["service"][1],
              f"a second Train call was not refused: {refusals['service']}")
        check(refusals["action_accepted"] is False, "a Train goal was accepted during a training")
        swap = self.swap_with(r.model_path, t0)
        check(swap.old_model != "" and swap.new_model != "", "swap message lacks model descriptions")
        p_new = self.predict()
        d = max_diff(p_new, p_old)
        check(d > 1e-9, f"predictions after the swap equal the old model's (max diff {d})")
        lat = lambda ids: round(statistics.median(self.preds[i][0] - self.sent[i] for i in ids) * 1e3, 2)
        self.summary.update(train_service_s=round(t_train, 3), predictions_during_training=len(got),
                            prediction_latency_ms_idle=lat(idle), prediction_latency_ms_training=lat(got),
                            train_message=r.message)
        trained_path = r.model_path

        # 2. A missing bag fails and keeps the model.
        missing = "/nonexistent/missing.mcap"
        r = self.call(self.train, Train.Request(bags=[missing], epochs=2), 30)
        check(not r.success and missing in r.message, f"Train with a missing bag: {r.success} {r.message!r}")
        check(self.predict() == p_new, "the model changed after a failed Train")

        # 3. LoadModel: bad files keep the model, a good one swaps.
        corrupt = os.path.join(a.work, "corrupt.json")
        with open(corrupt, "w") as f:
            f.write("{ not a model")
        for bad in ("/nonexistent/model.json", corrupt):
            r = self.call(self.load, LoadModel.Request(path=bad), 30)
            check(not r.success and bad in r.message, f"LoadModel({bad}): {r.success} {r.message!r}")
        check(self.predict() == p_new, "the model changed after a failed LoadModel")
        t0 = time.monotonic()
        r = self.call(self.load, LoadModel.Request(path=a.model), 30)
        t_load = time.monotonic() - t0
        check(r.success, f"LoadModel({a.model}) failed: {r.message}")
        self.swap_with(a.model, t0)
        t1 = time.monotonic()
        check(self.predict() == p_old, "after loading the first model again, predictions differ from its own")
        self.summary.update(load_model_call_s=round(t_load, 4), first_prediction_after_load_s=round(
            time.monotonic() - t1, 4), load_message=r.message)
        r = self.call(self.load, LoadModel.Request(path=trained_path), 30)
        check(r.success, f"LoadModel({trained_path}) failed: {r.message}")
        check(self.predict() == p_new, "the saved trained model predicts differently from the one swapped in")

        # 4. The action: feedback, result, swap.
        fb = []
        t0 = time.monotonic()
        h = self.send_goal(TrainAction.Goal(bags=[a.train_bag], epochs=a.action_epochs, seed=4), fb)
        check(h.accepted, "Train goal refused")
        res = self.result(h, 120)
        t_action = time.monotonic() - t0
        check(res.status == SUCCEEDED and res.result.success,
              f"action ended with status {res.status}: {res.result.message}")
        self.spin_until(lambda: len(fb) >= 1, 5, "feedback")
        epochs = [f.epoch for f in fb]
        check(epochs == sorted(epochs) and epochs[-1] == a.action_epochs and fb[-1].epochs == a.action_epochs,
              f"feedback epochs {epochs}")
        check(all(math.isfinite(f.train_loss) and math.isfinite(f.validation_loss) for f in fb), "NaN feedback")
        self.swap_with(res.result.model_path, t0)
        p_act = self.predict()
        check(max_diff(p_act, p_new) > 1e-9, "the action's model predicts as the previous one")
        self.summary.update(action_s=round(t_action, 3), feedback_messages=len(fb))

        # 5. Cancel: the model stays.
        fb = []
        t0 = time.monotonic()
        h = self.send_goal(TrainAction.Goal(bags=[a.train_bag], epochs=1_000_000, seed=5), fb)
        check(h.accepted, "Train goal refused")
        self.spin_until(lambda: len(fb) >= 2, 30, "two feedback messages")
        cf = h.cancel_goal_async()
        self.spin_until(cf.done, 10, "the cancel response")
        check(len(cf.result().goals_canceling) == 1, "cancel not accepted")
        res = self.result(h, 30)
        check(res.status == CANCELED and not res.result.success and "cancel" in res.result.message,
              f"cancelled goal ended with status {res.status}: {res.result.message!r}")
        self.summary.update(cancel_to_result_s=round(time.monotonic() - t0, 3))
        check(self.predict() == p_act, "the model changed after a cancelled training")
        check(not any(t >= t0 for t, _ in self.swaps), "a swap was announced after a cancelled training")

        # 6. Train on what the node recorded: play a trajectory, then no bags.
        traj = read_states(a.train_bag)[: a.played]
        for raw in traj:
            self.pub.publish(deserialize_message(raw, ParticleState))
            rclpy.spin_once(self.node, timeout_sec=0.005)
        ru.spin_until(rclpy, self.node, lambda: False, 1.0)
        t0 = time.monotonic()
        r = self.call(self.train, Train.Request(bags=[], epochs=a.epochs_recorded, seed=6), 120)
        check(r.success, f"Train on the recording failed: {r.message}")
        with open(r.model_path) as f:
            on = json.load(f)["trained_on"]
        check(a.record_dir in on["bag"], f"trained on {on['bag']}, not on bags of {a.record_dir}")
        check(on["states"] >= a.played, f"trained on {on['states']} states, fewer than the {a.played} played")
        self.swap_with(r.model_path, t0)
        self.summary.update(recorded_train_s=round(time.monotonic() - t0, 3), recorded_states=on["states"])

        # 6b. Fine-tune the served model: it starts from the served file's
        # weights and Adam state (the optimiser's step count carries on), and
        # a variant other than the served one is refused.
        with open(r.model_path) as f:
            base = json.load(f)
        t0 = time.monotonic()
        r = self.call(self.train, Train.Request(bags=[a.train_bag], epochs=2, seed=8, fine_tune=True), 120)
        check(r.success, f"fine-tuning failed: {r.message}")
        with open(r.model_path) as f:
            tuned = json.load(f)
        check(tuned["hyper"] == base["hyper"], "fine-tuning changed the architecture")
        check(tuned["optimizer"]["step"] >= base["optimizer"]["step"] + 2,
              f"Adam did not carry on: step {tuned['optimizer']['step']} after {base['optimizer']['step']}")
        check(tuned["weights"] != base["weights"], "fine-tuning did not change the weights")
        self.swap_with(r.model_path, t0)
        bad = self.call(self.train, Train.Request(bags=[a.train_bag], variant="gnode", epochs=1, fine_tune=True), 30)
        check(not bad.success and "fine-tune" in bad.message, f"fine-tuning as gnode: {bad.success} {bad.message!r}")
        self.summary.update(fine_tune_steps=[base["optimizer"]["step"], tuned["optimizer"]["step"]])

        # 7. Leave a long training running: the node must still stop on SIGINT.
        h = self.send_goal(TrainAction.Goal(bags=[a.train_bag], epochs=1_000_000, seed=7), [])
        check(h.accepted, "the last Train goal was refused")
        ru.spin_until(rclpy, self.node, lambda: False, 0.5)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--model", required=True, help="the model the node starts with")
    ap.add_argument("--state-bag", required=True, help="bag whose first state is published")
    ap.add_argument("--train-bag", required=True)
    ap.add_argument("--record-dir", required=True)
    ap.add_argument("--work", required=True, help="scratch folder")
    ap.add_argument("--epochs", type=int, default=150)
    ap.add_argument("--action-epochs", type=int, default=20)
    ap.add_argument("--epochs-recorded", type=int, default=5)
    ap.add_argument("--played", type=int, default=100)
    d = Driver(ap.parse_args())
    try:
        d.run()
    except Fail as e:
        print(f"FAIL: {e}")
        print(f"partial summary: {json.dumps(d.summary)}")
        sys.exit(1)
    except KeyboardInterrupt:
        sys.exit(130)
    print("TRAIN_SUMMARY " + json.dumps(d.summary))
    d.action.destroy()
    d.node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
