#!/usr/bin/env python3
"""Publishes states to a recording `mcgnode serve`, or reads what a killed node left.

Usage:
  kill_record.py publish --states N --rate HZ   (inside scripts/netns.sh, next to the node)
  kill_record.py read DIR                        (after the node was killed)

`publish` waits (bounded) until the node's input has matched, then publishes N
5-spring states at HZ with steps 0..N-1 and prints `PUBLISHED N`. `read` opens
every *.mcap in DIR as it is, unrepaired, with rosbags' AnyReader and with the
mcap streaming reader, and prints `READ {json}` with the ParticleState steps each
found; exits 1 with "FAIL: ..." when a reader cannot read a file.
"""

import argparse
import json
import math
import sys
import time
from pathlib import Path

STATE = "mcgnode_msgs/msg/ParticleState"


def publish(n, rate):
    import rclpy
    from geometry_msgs.msg import Vector3
    from mcgnode_msgs.msg import ParticleState

    rclpy.init()
    node = rclpy.create_node("kill_record_driver")
    pub = node.create_publisher(ParticleState, "/particle_state", 10)
    deadline = time.monotonic() + 20.0
    while pub.get_subscription_count() == 0:
        if time.monotonic() > deadline:
            raise SystemExit("FAIL: the node's input never matched within 20 s")
        rclpy.spin_once(node, timeout_sec=0.05)
    time.sleep(0.5)
    k = 5
    t0 = time.monotonic()
    for i in range(n):
        m = ParticleState()
        now = node.get_clock().now().to_msg()
        m.header.stamp = now
        m.header.frame_id = "lab"
        m.trajectory_id = 1
        m.step = i
        m.system = "spring"
        m.dimension = 2
        m.types = [0] * k
        m.masses = [1.0] * k
        m.positions = [Vector3(x=math.cos(2 * math.pi * j / k), y=math.sin(2 * math.pi * j / k), z=0.0)
                       for j in range(k)]
        m.velocities = [Vector3(x=0.1 * j, y=-0.1 * j, z=0.0) for j in range(k)]
        m.edge_a = list(range(k))
        m.edge_b = [(j + 1) % k for j in range(k)]
        m.edge_kind = [ParticleState.EDGE_SPRING] * k
        m.edge_rest_length = [1.0] * k
        m.edge_stiffness = [1.0] * k
        pub.publish(m)
        rclpy.spin_once(node, timeout_sec=0.0)
        wait = t0 + (i + 1) / rate - time.monotonic()
        if wait > 0:
            time.sleep(wait)
    print(f"PUBLISHED {n}", flush=True)
    node.destroy_node()
    rclpy.shutdown()


def read(directory):
    from mcap.stream_reader import StreamReader
    from mcap.records import Channel, Message, Schema
    from mcap_ros2.decoder import DecoderFactory
    from rosbags.highlevel import AnyReader

    bags = sorted(Path(directory).glob("*.mcap"))
    if not bags:
        raise SystemExit(f"FAIL: no .mcap files in {directory}")
    via_rosbags, via_mcap = [], []
    for bag in bags:
        try:
            with AnyReader([bag]) as r:
                for conn, _t, raw in r.messages():
                    if conn.msgtype == STATE:
                        via_rosbags.append(int(r.deserialize(raw, conn.msgtype).step))
        except Exception as e:  # noqa: BLE001 - the reason is the point
            raise SystemExit(f"FAIL: rosbags cannot read {bag.name}: {type(e).__name__}: {e}")
        schemas, channels = {}, {}
        decode = {}
        with open(bag, "rb") as fh:
            for rec in StreamReader(fh, skip_magic=False).records:
                if isinstance(rec, Schema):
                    schemas[rec.id] = rec
                elif isinstance(rec, Channel):
                    channels[rec.id] = rec
                elif isinstance(rec, Message):
                    ch = channels[rec.channel_id]
                    schema = schemas[ch.schema_id]
                    if schema.name != STATE:
                        continue
                    if ch.id not in decode:
                        decode[ch.id] = DecoderFactory().decoder_for(ch.message_encoding, schema)
                    via_mcap.append(int(decode[ch.id](rec.data).step))
    print("READ " + json.dumps({"bags": len(bags), "rosbags": via_rosbags, "mcap": via_mcap}))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = ap.add_subparsers(dest="cmd", required=True)
    p = sub.add_parser("publish")
    p.add_argument("--states", type=int, required=True)
    p.add_argument("--rate", type=float, required=True)
    r = sub.add_parser("read")
    r.add_argument("dir")
    args = ap.parse_args()
    if args.cmd == "publish":
        publish(args.states, args.rate)
    else:
        read(args.dir)


if __name__ == "__main__":
    sys.exit(main())
