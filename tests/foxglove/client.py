#!/usr/bin/env python3
"""A Foxglove WebSocket client, written on its own from the protocol's specification
(subprotocol foxglove.sdk.v1, the same protocol as foxglove.websocket.v1 under the name the
Foxglove SDK serves), with the `websockets` package: an independent peer for tdma-run's live
view.

It subscribes to the topics asked for, counts the messages received on each for --seconds, and
writes --out as JSON:

    {"/rov/pose": 12, "/camera/image": 1,            messages received per topic
     "first": {"/rov/pose": {...}},                   the first message of each, decoded
     "last": {"/rov/pose": {...}},                    the last message of each, decoded
     "log_time_ns": {"/rov/pose": 1700000000000},     the last message's log time
     "server": {...serverInfo...}, "advertised": [...topics...],
     "schemas": {"/rov/pose": "foxglove.PoseInFrame"}, "statuses": [...], "published": N,
     "closed_by_server": false}

--publish-twist advertises a client channel with schema geometry_msgs/Twist (as Foxglove's
Teleop panel does) and publishes the Twist at --rate Hz; --publish-order advertises /orders and
publishes each JSON order once. --garbage sends junk first: binary junk, an empty binary frame,
text that is not JSON, unknown operations, a message on a channel never advertised, channels
the server must refuse, bad JSON and bad orders on /orders, a NaN Twist, a huge message, and
connections that are cut mid-handshake or that offer no known subprotocol. --cafile trusts
that certificate for a wss:// URL. --source connects from that local address.
"""

import argparse
import json
import socket
import ssl
import struct
import sys
import time
from urllib.parse import urlparse

from websockets.exceptions import ConnectionClosed
from websockets.sync.client import connect

SUBPROTOCOL = "foxglove.sdk.v1"
MESSAGE_DATA = 1  # server binary opcode; also the client's message data opcode

DEFAULT_TWIST = '{"linear":{"x":0.5,"y":0,"z":0},"angular":{"x":0,"y":0,"z":0.25}}'


def client_message(channel_id, payload):
    return bytes([MESSAGE_DATA]) + struct.pack("<I", channel_id) + payload


def cut_connections(url):
    """Connections that go away: half a handshake, a wrong subprotocol, a drop after opening."""
    parsed = urlparse(url)
    with socket.create_connection((parsed.hostname, parsed.port), timeout=2) as s:
        s.sendall(b"GET / HTTP/1.1\r\nHost: x\r\nUpgrade: websocket\r\n")
    try:
        with connect(url, subprotocols=["nonsense.v9"], open_timeout=2):
            pass
    except Exception:
        pass
    ws = connect(url, subprotocols=[SUBPROTOCOL], open_timeout=2)
    ws.socket.close()


def garbage(ws, url):
    """Everything a confused or hostile client might send; the server must survive it all."""
    cut_connections(url)
    ws.send(b"\xff\x00\x01junk")
    ws.send(b"")
    ws.send("this is not json")
    ws.send('{"op":"nonsense"}')
    ws.send('{"op":"subscribe","subscriptions":"everything"}')
    ws.send('{"no_op":1}')
    ws.send("[1,2,3]")
    ws.send(client_message(999, b'{"type":"cancel"}'))
    ws.send(b"\x01\x02")
    ws.send(json.dumps({"op": "advertise", "channels": [
        {"id": 900, "topic": "/orders", "encoding": "protobuf", "schemaName": "x"},
        {"id": 901, "topic": "/elsewhere", "encoding": "json", "schemaName": "std_msgs/String"},
        {"id": 902, "topic": "/orders", "encoding": "json", "schemaName": ""},
        {"id": 903, "topic": "/garbage_twist", "encoding": "json",
         "schemaName": "geometry_msgs/Twist"},
    ]}))
    ws.send(json.dumps({"op": "advertise", "channels": [{"id": "nine", "topic": 5}]}))
    ws.send(json.dumps({"op": "advertise", "channels": [
        {"id": 902, "topic": "/orders", "encoding": "json", "schemaName": "again"}]}))
    ws.send(client_message(900, b"\x08\x01"))
    ws.send(client_message(901, b'"hello"'))
    ws.send(client_message(902, b"{"))
    ws.send(client_message(902, b"[1]"))
    ws.send(client_message(902, b'{"type":"goto"}'))
    ws.send(client_message(902, b'{"type":"unknown","ot":5,"body":"00"}'))
    ws.send(client_message(902, b"\xff\xfe"))
    ws.send(client_message(903, b'{"linear":{"x":null},"angular":{"z":0}}'))
    ws.send(client_message(903, b'{"linear":"fast"}'))
    ws.send(client_message(902, b'{"type":"cancel","pad":"' + b"x" * (1 << 20) + b'"}'))
    ws.send(json.dumps({"op": "unadvertise", "channelIds": [900, 901, 902, 903, 12345]}))
    ws.send(json.dumps({"op": "unsubscribe", "subscriptionIds": [4242]}))


def open_connection(url, within_s, context=None, source=None):
    """Connects (from the address `source`, if given), trying again while the server is not
    listening yet (a process starting)."""
    give_up = time.monotonic() + within_s
    while True:
        try:
            sock = None
            if source:
                parsed = urlparse(url)
                sock = socket.create_connection((parsed.hostname, parsed.port), timeout=5,
                                                source_address=(source, 0))
            return connect(url, subprotocols=[SUBPROTOCOL], max_size=None, open_timeout=5,
                           close_timeout=1, ssl=context, sock=sock)
        except (ConnectionRefusedError, ConnectionResetError):
            if time.monotonic() >= give_up:
                raise
            time.sleep(0.1)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--url", required=True)
    ap.add_argument("--topics", default="", help="comma-separated; empty: every topic")
    ap.add_argument("--seconds", type=float, default=3.0)
    ap.add_argument("--out", required=True)
    ap.add_argument("--publish-twist", nargs="?", const=DEFAULT_TWIST, default=None,
                    metavar="JSON")
    ap.add_argument("--twist-topic", default="/cmd_vel")
    ap.add_argument("--twist-schema", default="geometry_msgs/Twist")
    ap.add_argument("--rate", type=float, default=5.0, help="Twists per second")
    ap.add_argument("--publish-order", action="append", default=[], metavar="JSON")
    ap.add_argument("--connect-within", type=float, default=0.0, metavar="S",
                    help="retry a refused connection for this long")
    ap.add_argument("--cafile", help="a certificate to trust for wss://")
    ap.add_argument("--source", metavar="ADDRESS",
                    help="connect from this local address (e.g. 127.0.0.2, another loopback "
                         "address than the tests' other connections)")
    ap.add_argument("--garbage", action="store_true")
    ap.add_argument("--stall", action="store_true",
                    help="once subscribed, stop reading until the time is up (a stuck client)")
    args = ap.parse_args()

    wanted = [t for t in args.topics.split(",") if t]
    counts, first, last, log_time_ns, schemas = {}, {}, {}, {}, {}
    channels = {}  # server channel id -> channel
    subscriptions = {}  # subscription id -> topic
    statuses, advertised = [], []
    server = None
    published = 0
    next_subscription = 1
    twist_channel, order_channel = 1, 2
    next_twist = 0.0
    publishing_set_up = False
    closed_by_server = False

    deadline = time.monotonic() + args.seconds
    try:
        context = ssl.create_default_context(cafile=args.cafile) if args.cafile else None
        with open_connection(args.url, args.connect_within, context, args.source) as ws:
            while True:
                now = time.monotonic()
                if now >= deadline:
                    break
                if publishing_set_up and args.publish_twist is not None and now >= next_twist:
                    ws.send(client_message(twist_channel, args.publish_twist.encode()))
                    published += 1
                    next_twist = now + 1.0 / args.rate
                if args.stall and subscriptions:
                    time.sleep(max(0.0, deadline - now))
                    break
                try:
                    raw = ws.recv(timeout=min(0.05, deadline - now))
                except TimeoutError:
                    continue
                if isinstance(raw, str):
                    msg = json.loads(raw)
                    op = msg.get("op")
                    if op == "serverInfo":
                        server = msg
                        if args.garbage:
                            garbage(ws, args.url)
                        client_channels = []
                        if args.publish_twist is not None:
                            client_channels.append({"id": twist_channel, "topic": args.twist_topic,
                                                    "encoding": "json",
                                                    "schemaName": args.twist_schema})
                        if args.publish_order:
                            client_channels.append({"id": order_channel, "topic": "/orders",
                                                    "encoding": "json", "schemaName": ""})
                        if client_channels:
                            ws.send(json.dumps({"op": "advertise", "channels": client_channels}))
                            for order in args.publish_order:
                                ws.send(client_message(order_channel, order.encode()))
                                published += 1
                            publishing_set_up = True
                    elif op == "advertise":
                        subscribe = []
                        for ch in msg["channels"]:
                            channels[ch["id"]] = ch
                            advertised.append(ch["topic"])
                            schemas[ch["topic"]] = ch.get("schemaName")
                            if not wanted or ch["topic"] in wanted:
                                subscribe.append({"id": next_subscription, "channelId": ch["id"]})
                                subscriptions[next_subscription] = ch["topic"]
                                next_subscription += 1
                        if subscribe:
                            ws.send(json.dumps({"op": "subscribe", "subscriptions": subscribe}))
                    elif op == "status" and len(statuses) < 100:
                        statuses.append(msg)
                elif len(raw) >= 13 and raw[0] == MESSAGE_DATA:
                    subscription, stamp = struct.unpack_from("<IQ", raw, 1)
                    topic = subscriptions.get(subscription)
                    if topic is None:
                        continue
                    counts[topic] = counts.get(topic, 0) + 1
                    log_time_ns[topic] = stamp
                    try:
                        last[topic] = json.loads(raw[13:])
                    except ValueError:
                        last[topic] = None
                    first.setdefault(topic, last[topic])
    except ConnectionClosed:
        # The server went away (it was stopped): what was seen so far is the answer.
        closed_by_server = True

    result = dict(counts)
    result.update({"first": first, "last": last, "log_time_ns": log_time_ns, "server": server,
                   "advertised": advertised, "schemas": schemas, "statuses": statuses,
                   "published": published, "closed_by_server": closed_by_server})
    with open(args.out, "w") as f:
        json.dump(result, f)
    return 0


if __name__ == "__main__":
    sys.exit(main())
