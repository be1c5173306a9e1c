#!/usr/bin/env python3
"""Print the messages on a ROS 2 topic (a stand-in for `ros2 topic echo`).

Examples (on this machine, inside scripts/netns.sh with the node):
  python3 scripts/ros/echo.py /mcgnode/diagnostics --count 1
  python3 scripts/ros/echo.py /mcgnode/predicted_forces --json
  python3 scripts/ros/echo.py /particle_state --type mcgnode_msgs/msg/ParticleState --field positions

The type is discovered from the ROS graph unless --type is given. Once a
publisher has matched, "echo: listening on TOPIC [TYPE]" goes to stderr (with
volatile QoS, messages published before that are not seen). Messages are
printed as YAML documents separated by '---', or one JSON object per line.
Exits 0 after --count messages, 1 if --timeout passes first.
"""

import argparse
import json
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _rosutil as ru  # noqa: E402


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("topic", help="topic name, e.g. /mcgnode/diagnostics")
    ap.add_argument("--type", help="message type, e.g. mcgnode_msgs/msg/NodeDiagnostics (default: discovered)")
    ap.add_argument("--count", type=int, default=0, help="exit after this many messages (0 = never)")
    ap.add_argument("--timeout", type=float, default=0.0, help="give up after this many seconds (0 = never)")
    ap.add_argument("--best-effort", action="store_true", help="best-effort QoS (default reliable)")
    ap.add_argument("--depth", type=int, default=10, help="keep-last history depth")
    ap.add_argument("--json", action="store_true", help="one JSON object per line instead of YAML")
    ap.add_argument("--field", help="print only this field (dotted path, e.g. header.stamp)")
    args = ap.parse_args()

    rclpy = ru.require_rclpy()
    from rclpy.executors import ExternalShutdownException

    rclpy.init()
    node = rclpy.create_node("echo_%d" % os.getpid())
    start = time.monotonic()

    def remaining():
        return max(0.0, args.timeout - (time.monotonic() - start)) if args.timeout else 3600.0 * 24

    type_name = args.type
    if not type_name:
        found = {}

        def discovered():
            for name, types in node.get_topic_names_and_types():
                if name == args.topic and types:
                    found["t"] = types[0]
            return "t" in found

        if not ru.spin_until(rclpy, node, discovered, remaining()):
            sys.exit(f"error: topic {args.topic} not seen within {args.timeout} s (give --type to wait anyway)")
        type_name = found["t"]
    cls = ru.import_type(type_name)

    received = []

    def on_msg(msg):
        data = ru.to_plain(msg)
        if args.field:
            for part in args.field.split("."):
                data = data[part]
        if args.json:
            print(json.dumps(data), flush=True)
        else:
            import yaml

            print(yaml.safe_dump(data, sort_keys=False).rstrip(), flush=True)
            print("---", flush=True)
        received.append(1)

    sub = node.create_subscription(cls, args.topic, on_msg, ru.qos_profile(not args.best_effort, args.depth))
    try:
        if ru.spin_until(rclpy, node, lambda: sub.get_publisher_count() >= 1, remaining()):
            print(f"echo: listening on {args.topic} [{type_name}]", file=sys.stderr, flush=True)
        done = ru.spin_until(
            rclpy, node, lambda: args.count and len(received) >= args.count, remaining(), step=0.1
        )
    except (KeyboardInterrupt, ExternalShutdownException):
        done = True
    node.destroy_node()
    rclpy.try_shutdown()
    if not done:
        print(f"echo: timed out after {args.timeout} s with {len(received)} messages", file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
