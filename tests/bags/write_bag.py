#!/usr/bin/env python3
"""Writes a bag with the real ROS 2 writers, from messages described on standard input.

Usage: write_bag.py --kind KIND --out PATH < messages.ndjson

Each input line is a JSON object {"topic": "/points", "type": "sensor_msgs/msg/PointCloud2",
"log_time_ns": 100, "cdr": "<hex of the CDR payload>"}; messages are written in input order.

Kinds:
  mcap-zstd, mcap-lz4, mcap-none   one MCAP file (mcap.writer.Writer, ros2msg schemas, raw CDR),
                                   chunks compressed so (small chunks: several per file)
  mcap-unchunked                   one MCAP file without chunks
  db3, db3-message-zstd            a rosbag2 directory, sqlite3 storage (rosbags.rosbag2.Writer),
                                   payloads plain or each zstd-compressed (compression_mode MESSAGE)
  rosbag2-mcap                     a rosbag2 directory, mcap storage
  mcap-ros2                        one MCAP file written by mcap_ros2.writer.Writer (its default
                                   zstd) from message dicts: each input line's "cdr" is ignored and
                                   a small PointCloud2 (from "points": [[x, y, z], ...]) is written

Prints, one JSON line per message as written (read back with the official mcap reader for the
mcap kinds, so the payload is what is in the file): {"topic", "log_time_ns", "cdr"}.
"""

import argparse
import json
import struct
import sys

try:
    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer as McapWriter
    from mcap_ros2.writer import Writer as Ros2Writer
    from rosbags.rosbag2 import Writer as Rosbag2Writer
    from rosbags.rosbag2.writer import CompressionFormat, CompressionMode, StoragePlugin
    from rosbags.typesys import Stores, get_typestore
except ImportError as e:  # The test reports this line.
    print(f"write_bag.py: missing Python module ({e}); install with: "
          "python3 -m pip install mcap mcap-ros2-support rosbags", file=sys.stderr)
    sys.exit(3)

TYPESTORE = get_typestore(Stores.ROS2_HUMBLE)


def msgdef(typename):
    return TYPESTORE.generate_msgdef(typename, ros_version=2)[0]


def write_mcap(out, messages, compression, chunked, chunk_size=4096):
    """Writes (topic, type, log_time_ns, CDR bytes) messages as one MCAP file, raw CDR payloads
    under ros2msg schemas (small chunks by default: several per file)."""
    with open(out, "wb") as f:
        w = McapWriter(f, chunk_size=chunk_size, compression=compression, use_chunking=chunked)
        w.start(profile="ros2", library="rovlink tests")
        schemas, channels = {}, {}
        for topic, typ, t, data in messages:
            if typ not in schemas:
                schemas[typ] = w.register_schema(
                    name=typ, encoding="ros2msg", data=msgdef(typ).encode())
            if topic not in channels:
                channels[topic] = w.register_channel(
                    topic=topic, message_encoding="cdr", schema_id=schemas[typ])
            w.add_message(channel_id=channels[topic], log_time=t, publish_time=t, data=data)
        w.finish()


def write_rosbag2(out, messages, storage, compression=None):
    """Writes (topic, type, log_time_ns, CDR bytes) messages as a rosbag2 directory;
    compression: None, "message" or "file" (zstd)."""
    w = Rosbag2Writer(out, version=9, storage_plugin=storage)
    if compression:
        mode = {"message": CompressionMode.MESSAGE, "file": CompressionMode.FILE}[compression]
        w.set_compression(mode, CompressionFormat.ZSTD)
    w.open()
    conns = {}
    for topic, typ, t, data in messages:
        if topic not in conns:
            conns[topic] = w.add_connection(topic, typ, typestore=TYPESTORE)
        w.write(conns[topic], t, data)
    w.close()


def write_mcap_ros2(out, messages):
    with open(out, "wb") as f:
        w = Ros2Writer(f)
        schema = w.register_msgdef("sensor_msgs/msg/PointCloud2",
                                   msgdef("sensor_msgs/msg/PointCloud2"))
        for m in messages:
            points = m.get("points", [[1.0, 2.0, 3.0]])
            data = b"".join(struct.pack("<fff", *p) for p in points)
            t = int(m["log_time_ns"])
            msg = {
                "header": {"stamp": {"sec": t // 10**9, "nanosec": t % 10**9},
                           "frame_id": "sensor"},
                "height": 1, "width": len(points),
                "fields": [{"name": n, "offset": 4 * i, "datatype": 7, "count": 1}
                           for i, n in enumerate("xyz")],
                "is_bigendian": False, "point_step": 12, "row_step": 12 * len(points),
                "data": data, "is_dense": True,
            }
            w.write_message(topic=m["topic"], schema=schema, message=msg, log_time=t,
                            publish_time=t)
        w.finish()


def read_back(path):
    with open(path, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(log_time_order=False):
            print(json.dumps({"topic": channel.topic, "log_time_ns": message.log_time,
                              "cdr": message.data.hex()}))


def main():
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--kind", required=True)
    p.add_argument("--out", required=True)
    a = p.parse_args()
    messages = [json.loads(line) for line in sys.stdin if line.strip()]
    raw = [(m["topic"], m["type"], int(m["log_time_ns"]), bytes.fromhex(m["cdr"]))
           for m in messages]
    kinds = {
        "mcap-zstd": lambda: write_mcap(a.out, raw, CompressionType.ZSTD, True),
        "mcap-lz4": lambda: write_mcap(a.out, raw, CompressionType.LZ4, True),
        "mcap-none": lambda: write_mcap(a.out, raw, CompressionType.NONE, True),
        "mcap-unchunked": lambda: write_mcap(a.out, raw, CompressionType.NONE, False),
        "db3": lambda: write_rosbag2(a.out, raw, StoragePlugin.SQLITE3),
        "db3-message-zstd": lambda: write_rosbag2(a.out, raw, StoragePlugin.SQLITE3, "message"),
        "rosbag2-mcap": lambda: write_rosbag2(a.out, raw, StoragePlugin.MCAP),
        "mcap-ros2": lambda: write_mcap_ros2(a.out, messages),
    }
    if a.kind not in kinds:
        sys.exit(f"write_bag.py: --kind: expected one of {', '.join(kinds)}, found {a.kind!r}")
    kinds[a.kind]()
    if a.kind.startswith("mcap"):
        read_back(a.out)
    else:
        for m in messages:
            print(json.dumps({"topic": m["topic"], "log_time_ns": int(m["log_time_ns"]),
                              "cdr": m["cdr"]}))


if __name__ == "__main__":
    main()
