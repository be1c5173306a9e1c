#!/usr/bin/env python3
"""Rewrite an MCAP bag's messages as a bag written by standard ROS 2 tooling (rosbags).

Usage: write_rosbag2.py IN.mcap OUT [--storage mcap|sqlite3] [--compression none|message|file|chunk]
                        [--format zstd|lz4] [--split] [--version 8|9] [--no-definitions]

Independent of mcgnode's Rust code: every message is decoded with rosbags (types
registered from the schema text stored in IN) and serialised again by rosbags.

--storage mcap|sqlite3   rosbag2 directory OUT with metadata.yaml and OUT_0.mcap / OUT_0.db3.
--compression message    each message's CDR bytes compressed on its own (ros2 bag record
                         --compression-mode message); --format zstd uses rosbags' own
                         writer, --format lz4 compresses with lz4.frame and says so in
                         metadata.yaml.
--compression file       each storage file compressed whole (OUT_0.mcap.zstd).
--compression chunk      MCAP chunk compression: zstd through rosbags (storage-preset
                         compression), lz4 through the `mcap` writer as a plain file OUT
                         (no directory).
--split                  two storage files: the first half of the messages, then the rest.
--strip-field            set every ParticleState's field_status to FIELD_UNKNOWN (and gravity,
                         drag, force to zero), as a tool that does not know them writes.
--no-definitions         sqlite3 only: drop the message_definitions table, as rosbag2 bags
                         from before Iron lack it.
Run with the project's venv: .venv/bin/python3 (scripts/setup_venv.sh creates it).
"""

import argparse
import dataclasses
import shutil
import sqlite3
import sys
import tempfile
from pathlib import Path

from mcap.reader import make_reader


def read_input(path):
    """(topic, type, schema text, log time, raw bytes) of every message, in file order."""
    out = []
    with open(path, "rb") as fh:
        reader = make_reader(fh)
        for schema, channel, message in reader.iter_messages():
            out.append(
                (channel.topic, schema.name, schema.data.decode(), message.log_time, bytes(message.data))
            )
    return out


def typestore_for(messages):
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    store = get_typestore(Stores.ROS2_KILTED)
    done = set()
    for _, typ, text, _, _ in messages:
        if typ in done or typ in store.fielddefs:
            continue
        main = text.split("=" * 80)[0]
        store.register(get_types_from_msg(main, typ))
        done.add(typ)
    return store


def strip(msg, on):
    """The message with its field entries unknown (when `on` and it has them)."""
    if not on or not hasattr(msg, "field_status"):
        return msg
    zero = dataclasses.replace(msg.gravity, x=0.0, y=0.0, z=0.0)
    return dataclasses.replace(msg, field_status=0, gravity=zero, drag=0.0, force=zero)


def write_dir(out, messages, store, args):
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.rosbag2.enums import CompressionFormat, CompressionMode

    plugin = StoragePlugin.MCAP if args.storage == "mcap" else StoragePlugin.SQLITE3
    writer = Writer(out, version=args.version, storage_plugin=plugin)
    lz4_messages = args.compression == "message" and args.format == "lz4"
    if args.compression == "message" and not lz4_messages:
        writer.set_compression(CompressionMode.MESSAGE, CompressionFormat.ZSTD)
    elif args.compression == "file":
        if args.format != "zstd":
            sys.exit("rosbags compresses files with zstd only")
        writer.set_compression(CompressionMode.FILE, CompressionFormat.ZSTD)
    elif args.compression == "chunk":
        writer.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    writer.open()
    conns = {}
    for topic, typ, _, log_time, data in messages:
        if topic not in conns:
            conns[topic] = writer.add_connection(topic, typ, typestore=store)
        msg = strip(store.deserialize_cdr(data, typ), args.strip_field)
        raw = bytes(store.serialize_cdr(msg, typ))
        if lz4_messages:
            import lz4.frame

            raw = lz4.frame.compress(raw)
        writer.write(conns[topic], log_time, raw)
    writer.close()
    if lz4_messages:
        meta = out / "metadata.yaml"
        text = meta.read_text()
        text = text.replace("compression_format: ''", "compression_format: lz4")
        text = text.replace("compression_mode: ''", "compression_mode: MESSAGE")
        meta.write_text(text)


def write_lz4_chunks(out, messages, store, args):
    from mcap.writer import CompressionType, Writer

    with open(out, "wb") as fh:
        w = Writer(fh, compression=CompressionType.LZ4)
        w.start(profile="ros2", library="write_rosbag2.py")
        schemas, channels = {}, {}
        for topic, typ, text, log_time, data in messages:
            if typ not in schemas:
                schemas[typ] = w.register_schema(typ, "ros2msg", text.encode())
            if topic not in channels:
                channels[topic] = w.register_channel(topic, "cdr", schemas[typ])
            msg = strip(store.deserialize_cdr(data, typ), args.strip_field)
            raw = bytes(store.serialize_cdr(msg, typ))
            w.add_message(channels[topic], log_time=log_time, data=raw, publish_time=log_time)
        w.finish()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("input", type=Path)
    ap.add_argument("out", type=Path)
    ap.add_argument("--storage", choices=["mcap", "sqlite3"], default="mcap")
    ap.add_argument("--compression", choices=["none", "message", "file", "chunk"], default="none")
    ap.add_argument("--format", choices=["zstd", "lz4"], default="zstd")
    ap.add_argument("--version", type=int, choices=[8, 9], default=9)
    ap.add_argument("--split", action="store_true")
    ap.add_argument("--no-definitions", action="store_true")
    ap.add_argument("--strip-field", action="store_true")
    args = ap.parse_args()

    messages = read_input(args.input)
    store = typestore_for(messages)
    if args.compression == "chunk" and args.format == "lz4":
        write_lz4_chunks(args.out, messages, store, args)
        return 0
    if not args.split:
        write_dir(args.out, messages, store, args)
    else:
        half = len(messages) // 2
        write_dir(args.out, messages[:half], store, args)
        with tempfile.TemporaryDirectory() as tmp:
            second = Path(tmp) / "second"
            write_dir(second, messages[half:], store, args)
            (name,) = [p.name for p in second.iterdir() if p.name != "metadata.yaml"]
            new_name = args.out.name + "_1" + "".join(Path(name).suffixes)
            shutil.move(str(second / name), str(args.out / new_name))
        from ruamel.yaml import YAML

        yaml = YAML(typ="safe")
        meta_path = args.out / "metadata.yaml"
        meta = yaml.load(meta_path.read_text())
        info = meta["rosbag2_bagfile_information"]
        info["relative_file_paths"].append(new_name)
        info["files"].append(dict(info["files"][0], path=new_name))
        with open(meta_path, "w") as fh:
            yaml.dump(meta, fh)
    if args.no_definitions:
        if args.storage != "sqlite3":
            sys.exit("--no-definitions applies to --storage sqlite3")
        for db in args.out.glob("*.db3"):
            con = sqlite3.connect(db)
            con.execute("DROP TABLE message_definitions")
            con.commit()
            con.close()
    return 0


if __name__ == "__main__":
    sys.exit(main())
