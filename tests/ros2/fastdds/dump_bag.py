#!/usr/bin/env python3
"""Dumps an MCAP bag's ROS 2 messages for the Fast DDS peer (fastdds_peer play): each message's
CDR bytes, exactly as the bag stores them, to DIR/NNNNN.cdr, and DIR/index.tsv with one line per
message in log-time order: topic, ROS type, file. Only the types the peer knows
(PointCloud2, TFMessage). Prints the counts per topic as one JSON line.

Usage: dump_bag.py BAG DIR
"""
import json
import os
import sys

from mcap.reader import make_reader

TYPES = {"sensor_msgs/msg/PointCloud2", "tf2_msgs/msg/TFMessage"}


def main():
    bag, out = sys.argv[1], sys.argv[2]
    os.makedirs(out, exist_ok=True)
    counts = {}
    with open(bag, "rb") as f, open(os.path.join(out, "index.tsv"), "w") as index:
        reader = make_reader(f)
        for n, (schema, channel, message) in enumerate(reader.iter_messages(log_time_order=True)):
            if schema is None or schema.name not in TYPES:
                continue
            path = os.path.join(out, "%05d.cdr" % n)
            with open(path, "wb") as m:
                m.write(message.data)
            index.write("%s\t%s\t%s\n" % (channel.topic, schema.name, path))
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
    print(json.dumps(counts))


if __name__ == "__main__":
    sys.exit(main())
