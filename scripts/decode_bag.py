#!/usr/bin/env python3
"""Decode the ParticleState messages of an MCAP bag, independently of mcgnode's Rust code.

Usage: decode_bag.py BAG [--decoder mcap|rosbags] [--bits]

--decoder mcap     uses the `mcap` reader with `mcap_ros2.decoder` (default);
--decoder rosbags  uses rosbags.highlevel.AnyReader (types from the bag's schema).
--bits             writes every float64 as its IEEE-754 bit pattern (an integer),
                   so a test can compare values exactly.

Prints one JSON object: {"decoder", "metadata": {name: {key: value}}, "messages": [...]},
one message entry per ParticleState message in log-time order. Metadata records are
read with the mcap reader in both modes (rosbags does not expose them).
Run with the project's venv: .venv/bin/python3 (scripts/setup_venv.sh creates it).
"""

import argparse
import json
import struct
import sys
from pathlib import Path

TYPE = "mcgnode_msgs/msg/ParticleState"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("bag", type=Path)
    ap.add_argument("--decoder", choices=["mcap", "rosbags"], default="mcap")
    ap.add_argument("--bits", action="store_true")
    args = ap.parse_args()

    def f(x):
        x = float(x)
        return struct.unpack("<Q", struct.pack("<d", x))[0] if args.bits else x

    def ints(a):
        # rosbags gives numpy arrays, mcap_ros2 lists (or bytes for uint8[]).
        return [int(x) for x in (a.tolist() if hasattr(a, "tolist") else a)]

    def floats(a):
        return [f(x) for x in (a.tolist() if hasattr(a, "tolist") else a)]

    def vecs(a):
        return [[f(p.x), f(p.y), f(p.z)] for p in a]

    def entry(topic, log_time, m):
        return {
            "topic": topic,
            "log_time": int(log_time),
            "sec": int(m.header.stamp.sec),
            "nanosec": int(m.header.stamp.nanosec),
            "frame_id": m.header.frame_id,
            "trajectory_id": int(m.trajectory_id),
            "step": int(m.step),
            "system": m.system,
            "dimension": int(m.dimension),
            "types": ints(m.types),
            "masses": floats(m.masses),
            "positions": vecs(m.positions),
            "velocities": vecs(m.velocities),
            "accelerations": vecs(m.accelerations),
            "edge_a": ints(m.edge_a),
            "edge_b": ints(m.edge_b),
            "edge_kind": ints(m.edge_kind),
            "edge_rest_length": floats(m.edge_rest_length),
            "edge_stiffness": floats(m.edge_stiffness),
            "anchors": vecs(m.anchors),
            # Messages of the first layout have no field entries: unknown (0).
            "field_status": int(getattr(m, "field_status", 0)),
            "gravity": vecs([m.gravity])[0] if hasattr(m, "gravity") else [f(0), f(0), f(0)],
            "drag": f(getattr(m, "drag", 0.0)),
            "force": vecs([m.force])[0] if hasattr(m, "force") else [f(0), f(0), f(0)],
            # Messages from before contacts: radius 0, no kinematic particle.
            "interaction_radius": f(getattr(m, "interaction_radius", 0.0)),
            "kinematic": [bool(x) for x in getattr(m, "kinematic", [])],
        }

    from mcap.reader import make_reader

    messages = []
    metadata = {}
    with open(args.bag, "rb") as fh:
        if args.decoder == "mcap":
            from mcap_ros2.decoder import DecoderFactory

            reader = make_reader(fh, decoder_factories=[DecoderFactory()])
            for schema, channel, message, m in reader.iter_decoded_messages(log_time_order=True):
                if schema is not None and schema.name == TYPE:
                    messages.append(entry(channel.topic, message.log_time, m))
        else:
            reader = make_reader(fh)
        for rec in reader.iter_metadata():
            metadata.setdefault(rec.name, {}).update(rec.metadata)

    if args.decoder == "rosbags":
        from rosbags.highlevel import AnyReader

        with AnyReader([args.bag]) as r:
            conns = [c for c in r.connections if c.msgtype == TYPE]
            for conn, timestamp, raw in r.messages(connections=conns):
                messages.append(entry(conn.topic, timestamp, r.deserialize(raw, conn.msgtype)))

    json.dump({"decoder": args.decoder, "metadata": metadata, "messages": messages}, sys.stdout)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except BrokenPipeError:
        sys.exit(1)
    except Exception as err:  # one clear line instead of a traceback
        print(f"decode_bag.py: {' '.join(sys.argv[1:])}: {type(err).__name__}: {err}", file=sys.stderr)
        sys.exit(1)
