#!/usr/bin/env python3
"""Writes a control MCAP log that Foxglove Studio must refuse, for scripts/foxglove-studio.sh.

Usage: bad_log.py OUT.mcap

Two channels: /rov/status, which Studio reads, and /link/frames, whose JSON Schema has a type
array (`"type": ["number", "null"]`), the construct of issue 28 that Studio's JSON Schema
reader refuses (the Problems list says `Unsupported type ["number","null"] for t_sent_s`). The script opens it as it opens the
sessions' logs and requires check.py to fail on it with that message: a check that cannot see
a problem would pass it.
"""

import json
import sys

from mcap.writer import Writer

GOOD = {"title": "rovlink.Status", "type": "object", "properties": {"depth_m": {"type": "number"}}}
BAD = {
    "title": "rovlink.LinkFrame",
    "type": "object",
    "properties": {"bytes": {"type": "integer"}, "t_sent_s": {"type": ["number", "null"]}},
}


def main():
    if len(sys.argv) != 2:
        print("usage: bad_log.py OUT.mcap", file=sys.stderr)
        return 2
    with open(sys.argv[1], "wb") as file:
        writer = Writer(file)
        writer.start(profile="", library="rovlink foxglove-studio control")
        channels = {}
        for topic, schema in [("/rov/status", GOOD), ("/link/frames", BAD)]:
            schema_id = writer.register_schema(
                name=schema["title"], encoding="jsonschema", data=json.dumps(schema).encode()
            )
            channels[topic] = writer.register_channel(
                topic=topic, message_encoding="json", schema_id=schema_id
            )
        for index in range(10):
            t_ns = index * 100_000_000
            for topic, message in [
                ("/rov/status", {"depth_m": 0.5}),
                ("/link/frames", {"bytes": 16, "t_sent_s": index / 10}),
            ]:
                data = json.dumps(message).encode()
                writer.add_message(channels[topic], log_time=t_ns, publish_time=t_ns, data=data)
        writer.finish()
    return 0


if __name__ == "__main__":
    sys.exit(main())
