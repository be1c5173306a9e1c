#!/usr/bin/env python3
"""Call a ROS 2 service (a stand-in for `ros2 service call`).

The request is YAML or JSON (JSON is YAML), given inline or with --file:
  python3 scripts/ros/call.py /mcgnode/rollout mcgnode_msgs/srv/Rollout --file req.yaml
  python3 scripts/ros/call.py /mcgnode/load_model mcgnode_msgs/srv/LoadModel '{path: model.bin}'

Waits up to --timeout seconds for the service and for the response (the first
call after a server starts can take a few seconds while DDS matches). Prints
the response as YAML (or JSON with --json); exits 1 on timeout.
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
    ap.add_argument("service", help="service name, e.g. /mcgnode/rollout")
    ap.add_argument("type", help="service type, e.g. mcgnode_msgs/srv/Rollout")
    ap.add_argument("request", nargs="?", default="{}", help="request fields as YAML/JSON (default {})")
    ap.add_argument("--file", help="read the request from this YAML/JSON file instead")
    ap.add_argument("--timeout", type=float, default=30.0, help="seconds to wait in total")
    ap.add_argument("--json", action="store_true", help="print the response as JSON")
    args = ap.parse_args()

    import yaml

    text = open(args.file).read() if args.file else args.request
    try:
        data = yaml.safe_load(text) or {}
    except yaml.YAMLError as e:
        sys.exit(f"error: request is not valid YAML/JSON: {e}")

    rclpy = ru.require_rclpy()
    srv = ru.import_type(args.type)
    try:
        request = ru.fill(srv.Request(), data)
    except ValueError as e:
        sys.exit(f"error: {e}")

    rclpy.init()
    node = rclpy.create_node("call_%d" % os.getpid())
    client = node.create_client(srv, args.service)
    start = time.monotonic()
    if not client.wait_for_service(timeout_sec=args.timeout):
        sys.exit(f"error: service {args.service} not available within {args.timeout} s")
    sent = time.monotonic()
    future = client.call_async(request)
    left = max(0.1, args.timeout - (time.monotonic() - start))
    rclpy.spin_until_future_complete(node, future, timeout_sec=left)
    if not future.done():
        sys.exit(f"error: no response from {args.service} within {args.timeout} s")
    took = time.monotonic() - sent
    data = ru.to_plain(future.result())
    if args.json:
        print(json.dumps(data))
    else:
        print(yaml.safe_dump(data, sort_keys=False).rstrip())
    print(f"call: response in {took * 1000:.1f} ms", file=sys.stderr)
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
