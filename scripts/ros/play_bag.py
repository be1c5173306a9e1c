#!/usr/bin/env python3
"""Publish a bag's ParticleState messages onto a topic (a stand-in for `ros2 bag play`).

  python3 scripts/ros/play_bag.py bags/spring5.mcap                  # recorded rate
  python3 scripts/ros/play_bag.py run.mcap --topic /particle_state --rate 50
  python3 scripts/ros/play_bag.py run.mcap --speed 10 --limit 100

Reads every mcgnode_msgs/msg/ParticleState message of an MCAP bag (or only
those of --bag-topic) and publishes it, at the recorded pace (log times,
scaled by --speed) or at a fixed --rate in Hz. The output topic defaults to
the recorded topic. It first waits (up to --timeout s) for --wait-subscribers
subscribers, since messages sent before a subscriber matches are lost. Bags of
the first ParticleState layout (no field entries) are played with the field
unknown.
"""

import argparse
import os
import sys
import time

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import _rosutil as ru  # noqa: E402

STATE_TYPE = "mcgnode_msgs/msg/ParticleState"


def old_decoder(schema):
    """A decoder for messages of `schema` as stored in the bag (mcap_ros2)."""
    from mcap_ros2.decoder import DecoderFactory

    return DecoderFactory().decoder_for("cdr", schema)


def plain_from(obj, cls):
    """The fields of `cls` that a decoded message `obj` has, as nested dicts/lists."""
    out = {}
    for key, ftype in cls.get_fields_and_field_types().items():
        if not hasattr(obj, key):
            continue
        value = getattr(obj, key)
        m = ru._SEQ.match(ftype)
        if m:
            elem = ru._element_class(m.group(1) or m.group(2))
            value = [plain_from(x, elem) for x in value] if elem else list(value)
        elif ru._element_class(ftype) is not None:
            value = plain_from(value, ru._element_class(ftype))
        out[key] = value
    return out


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("bag", help="MCAP file")
    ap.add_argument("--topic", help="topic to publish on (default: the recorded topic)")
    ap.add_argument("--bag-topic", help="play only this recorded topic")
    rate = ap.add_mutually_exclusive_group()
    rate.add_argument("--rate", type=float, help="publish at this fixed rate, Hz")
    rate.add_argument("--speed", type=float, default=1.0, help="recorded pace times this (default 1)")
    ap.add_argument("--limit", type=int, default=0, help="stop after this many messages (0 = all)")
    ap.add_argument("--wait-subscribers", type=int, default=1, help="subscribers to wait for (default 1)")
    ap.add_argument("--timeout", type=float, default=30.0, help="seconds to wait for subscribers")
    ap.add_argument("--settle", type=float, default=1.0,
                    help="seconds to wait after the subscribers matched, so that they match us too (default 1)")
    ap.add_argument("--best-effort", action="store_true", help="best-effort QoS (default reliable)")
    args = ap.parse_args()
    if args.rate is not None and not args.rate > 0:
        sys.exit("error: --rate must be > 0")
    if not args.speed > 0:
        sys.exit("error: --speed must be > 0")

    try:
        from mcap.reader import make_reader
    except ImportError:
        sys.exit(f"error: the mcap package is missing;\n{ru.SETUP_HINT}")
    rclpy = ru.require_rclpy()
    from rclpy.serialization import deserialize_message

    cls = ru.import_type(STATE_TYPE)

    with open(args.bag, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        if summary is None:
            sys.exit(f"error: {args.bag} has no summary (not a finished MCAP file?)")
        topics = sorted(
            {
                ch.topic
                for ch in summary.channels.values()
                if summary.schemas.get(ch.schema_id) is not None
                and summary.schemas[ch.schema_id].name == STATE_TYPE
                and (args.bag_topic is None or ch.topic == args.bag_topic)
            }
        )
        if not topics:
            sys.exit(f"error: no {STATE_TYPE} messages in {args.bag}" + (
                f" on {args.bag_topic}" if args.bag_topic else ""))
        if args.topic is None and len(topics) > 1:
            sys.exit(f"error: {args.bag} holds several state topics {topics}: choose with --bag-topic or --topic")
        out_topic = args.topic or topics[0]

        rclpy.init()
        node = rclpy.create_node("play_bag_%d" % os.getpid())
        pub = node.create_publisher(cls, out_topic, ru.qos_profile(not args.best_effort))
        if args.wait_subscribers > 0 and not ru.spin_until(
            rclpy, node, lambda: pub.get_subscription_count() >= args.wait_subscribers, args.timeout
        ):
            sys.exit(f"error: fewer than {args.wait_subscribers} subscribers on {out_topic} after {args.timeout} s")
        # Our side seeing the subscriber does not mean the subscriber has
        # matched our new writer yet: a volatile reader that matches late skips
        # what was sent before. Let discovery settle both ways.
        if args.wait_subscribers > 0 and args.settle > 0:
            ru.spin_until(rclpy, node, lambda: False, args.settle)

        decoders = {}
        sent = 0
        first_log = None
        t0 = time.monotonic()
        for _schema, channel, message in reader.iter_messages(topics=topics, log_time_order=True):
            if args.rate is not None:
                due = t0 + sent / args.rate
            else:
                if first_log is None:
                    first_log = message.log_time
                due = t0 + (message.log_time - first_log) * 1e-9 / args.speed
            delay = due - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            try:
                if b"interaction_radius" in _schema.data:
                    msg = deserialize_message(message.data, cls)
                else:
                    # An earlier ParticleState layout (no contact or no field
                    # entries): decode it with the bag's own schema; what it
                    # lacks keeps its default (radius 0, field FIELD_UNKNOWN).
                    old = decoders.setdefault(_schema.id, old_decoder(_schema))(message.data)
                    msg = ru.fill(cls(), plain_from(old, cls))
            except Exception as e:  # noqa: BLE001 - report which message and go on
                print(f"play_bag: skipping message {sent} on {channel.topic}: {e}", file=sys.stderr)
                continue
            pub.publish(msg)
            sent += 1
            rclpy.spin_once(node, timeout_sec=0)
            if args.limit and sent >= args.limit:
                break
        # Give reliable delivery a moment to flush before tearing down.
        ru.spin_until(rclpy, node, lambda: False, 0.5)
        print(f"play_bag: published {sent} messages on {out_topic} in {time.monotonic() - t0:.2f} s",
              file=sys.stderr)
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
