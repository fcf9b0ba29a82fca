#!/usr/bin/env python3
"""Reads an `octo-delta apply --mcap` file as a player would and prints what it shows.

Usage: check_view.py VIEW.mcap

Checks with the official readers: the file parses (Python `mcap`), it has one channel,
/octo_delta/view, schema foxglove.SceneUpdate in jsonschema encoding, JSON messages, and
every message validates against the schema the file carries (Python `jsonschema`). Then it
replays the messages in log-time order (deletions by id, entities replacing by id) and prints
one JSON object: the message count, log and publish times (ns), and the cubes in the scene at
the end, per namespace ("fine", "coarse"), each [x, y, z, size_x, size_y, size_z, r, g, b, a].

Exit 0 when it could read the file, 1 when a check failed (the reason on stderr), 3 when a
Python package is missing (what to install on stderr).
"""
import json
import sys

try:
    from mcap.reader import make_reader
    import jsonschema
except ImportError as e:
    sys.stderr.write(
        f"check_view.py: {e}: install the Python packages mcap and jsonschema "
        "(python3 -m pip install mcap jsonschema)\n"
    )
    sys.exit(3)


def fail(message):
    sys.stderr.write(f"check_view.py: {message}\n")
    sys.exit(1)


def main(path):
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        if summary is None:
            fail("no summary section")
        channels = list(summary.channels.values())
        if [c.topic for c in channels] != ["/octo_delta/view"]:
            fail(f"channels {[c.topic for c in channels]}")
        channel = channels[0]
        schema = summary.schemas[channel.schema_id]
        if (schema.name, schema.encoding, channel.message_encoding) != (
            "foxglove.SceneUpdate",
            "jsonschema",
            "json",
        ):
            fail(f"schema {schema.name} {schema.encoding}, messages {channel.message_encoding}")
        validator_class = jsonschema.validators.validator_for(json.loads(schema.data))
        validator = validator_class(json.loads(schema.data))
        scene = {}
        log_times, publish_times = [], []
        for _, _, message in reader.iter_messages(log_time_order=True):
            update = json.loads(message.data)
            errors = sorted(validator.iter_errors(update), key=lambda e: list(e.path))
            if errors:
                fail(f"message {len(log_times)}: {errors[0].message} at {list(errors[0].path)}")
            log_times.append(message.log_time)
            publish_times.append(message.publish_time)
            for d in update["deletions"]:
                if d["type"] != 0 or d["id"] not in scene:
                    fail(f"message {len(log_times) - 1}: deletion of {d['id']} not in the scene")
                del scene[d["id"]]
            for e in update["entities"]:
                stamp = e["timestamp"]["sec"] * 10**9 + e["timestamp"]["nsec"]
                if stamp != message.log_time or e["frame_id"] != "map":
                    fail(f"entity {e['id']}: stamp {stamp}, frame {e['frame_id']}")
                scene[e["id"]] = e["cubes"]
    cubes = {"fine": [], "coarse": []}
    for eid, entity_cubes in scene.items():
        namespace = eid.split("/")[0]
        if namespace not in cubes:
            fail(f"entity id {eid}: namespace is not fine or coarse")
        for c in entity_cubes:
            p, s, k = c["pose"]["position"], c["size"], c["color"]
            cubes[namespace].append(
                [p["x"], p["y"], p["z"], s["x"], s["y"], s["z"], k["r"], k["g"], k["b"], k["a"]]
            )
    json.dump(
        {
            "messages": len(log_times),
            "log_time_ns": log_times,
            "publish_time_ns": publish_times,
            "entities": len(scene),
            "fine": cubes["fine"],
            "coarse": cubes["coarse"],
        },
        sys.stdout,
    )


if __name__ == "__main__":
    if len(sys.argv) != 2:
        fail("usage: check_view.py VIEW.mcap")
    main(sys.argv[1])
