#!/usr/bin/env python3
"""Checks that Foxglove can read every channel of an MCAP file, with the official readers.

Usage: check_schemas.py FILE.mcap

For every channel with a `jsonschema` schema: the schema uses only what Foxglove's JSON Schema
reader takes (no type arrays such as ["number", "null"], no oneOf / anyOf / allOf, a "type" on
every property, objects with "properties", arrays with "items"), and every message on it
(Python `mcap`) validates against it (Python `jsonschema`). Prints one JSON object, the number
of messages checked per topic.

Exit 0 when every check passed, 1 when one failed (the reason on stderr, naming the topic and
the schema path or message), 3 when a Python package is missing.
"""
import json
import sys

try:
    from mcap.reader import make_reader
    import jsonschema
except ImportError as e:
    sys.stderr.write(
        f"check_schemas.py: {e}: install the Python packages mcap and jsonschema "
        "(python3 -m pip install mcap jsonschema)\n"
    )
    sys.exit(3)


def fail(message):
    sys.stderr.write(f"check_schemas.py: {message}\n")
    sys.exit(1)


def problems(schema, path="$"):
    """What Foxglove's reader would refuse in `schema`, as (path, why) pairs."""
    out = []
    if not isinstance(schema, dict):
        return [(path, "not an object")]
    for word in ("oneOf", "anyOf", "allOf"):
        if word in schema:
            out.append((path, f"uses {word}"))
    kind = schema.get("type")
    if kind is None:
        out.append((path, "has no type"))
    elif not isinstance(kind, str):
        out.append((path, f"type is {json.dumps(kind)}, not one name"))
    if kind == "object":
        props = schema.get("properties")
        if not isinstance(props, dict):
            out.append((path, "an object without properties"))
        else:
            for name, sub in props.items():
                out.extend(problems(sub, f"{path}.{name}"))
    if kind == "array":
        if "items" not in schema:
            out.append((path, "an array without items"))
        else:
            out.extend(problems(schema["items"], f"{path}[]"))
    return out


def main(path):
    counts = {}
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        if summary is None:
            fail(f"{path}: no summary section")
        validators = {}
        for channel in summary.channels.values():
            schema = summary.schemas.get(channel.schema_id)
            if schema is None or schema.encoding != "jsonschema":
                continue
            if channel.message_encoding != "json":
                fail(f"{channel.topic}: messages in {channel.message_encoding}, not json")
            parsed = json.loads(schema.data)
            for where, why in problems(parsed):
                fail(f"{channel.topic}: schema {schema.name} at {where}: {why}")
            cls = jsonschema.validators.validator_for(parsed)
            cls.check_schema(parsed)
            validators[channel.id] = (channel.topic, cls(parsed))
            counts[channel.topic] = 0
        for _, channel, message in reader.iter_messages():
            if channel.id not in validators:
                continue
            topic, validator = validators[channel.id]
            data = json.loads(message.data)
            errors = sorted(validator.iter_errors(data), key=lambda e: list(e.path))
            if errors:
                fail(
                    f"{topic}: message {counts[topic]}: {errors[0].message} "
                    f"at {list(errors[0].path)}"
                )
            counts[topic] += 1
    print(json.dumps(counts, sort_keys=True))


if __name__ == "__main__":
    if len(sys.argv) != 2:
        fail("usage: check_schemas.py FILE.mcap")
    main(sys.argv[1])
