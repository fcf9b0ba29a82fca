#!/usr/bin/env python3
"""Loads a MAVLink 2 signing key into an ArduPilot autopilot (ArduSub) with SETUP_SIGNING, over
a trusted link (the wired USB or tether link, before the dive; never over a radio or an
acoustic link), and checks that the autopilot then signs with it.

The key file is tdma-run's --mavlink-key-file: 64 hex digits and an optional newline, or exactly
32 raw bytes, a regular file of this user's that group and others can neither read nor write
(as ssh wants a private key). Make one with:
  head -c 32 /dev/urandom | xxd -p -c 64 > key; chmod 600 key

What it does: waits for the autopilot's HEARTBEAT, sends SETUP_SIGNING (the key and the
current time as the initial timestamp, in 10 us units since 2015-01-01) to it, then takes only
messages signed with the key and waits for the autopilot's HEARTBEAT again, sending
SETUP_SIGNING again every 2 s meanwhile. ArduPilot keeps the key in its storage (it survives
a reboot) and from then on refuses unsigned messages on every MAVLink port but the first
(SERIAL0, USB, which it takes as secure), except RADIO_STATUS. With --disable it sends an
all-zero key, which turns signing off, and waits for an unsigned HEARTBEAT.

Exit 0 once the autopilot answers as asked (a line on stderr says so), 1 when it does not
within --timeout, 2 for a bad key file or usage.

Usage: mavlink-setup-signing.py --connect tcp:127.0.0.1:5760 --key-file key
       mavlink-setup-signing.py --connect /dev/ttyACM0 --baud 115200 --key-file key
       mavlink-setup-signing.py --connect tcp:127.0.0.1:5760 --disable
"""

import argparse
import os
import stat
import sys
import time

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402

EPOCH_2015_S = 1420070400


def fail(code, text):
    print(f"mavlink-setup-signing: {text}", file=sys.stderr)
    sys.exit(code)


def read_key(path):
    """The key in `path`, checked as ssh checks a private key; exits 2 saying what is wrong."""
    try:
        meta = os.lstat(path)
    except OSError as error:
        fail(2, f"--key-file {path}: cannot read: {error.strerror}")
    if not stat.S_ISREG(meta.st_mode):
        fail(2, f"--key-file {path}: expected a regular file")
    if meta.st_uid != os.geteuid():
        fail(2, f"--key-file {path}: owned by uid {meta.st_uid}, not by this user: refused")
    if meta.st_mode & 0o077:
        fail(2, f"--key-file {path}: permissions {meta.st_mode & 0o7777:04o} are too open; chmod 600 {path}")
    with open(path, "rb") as f:
        data = f.read(67)
    if len(data) == 32:
        return data
    text = data.rstrip(b"\r\n")
    try:
        if len(text) != 64:
            raise ValueError
        return bytes.fromhex(text.decode("ascii"))
    except (ValueError, UnicodeDecodeError):
        fail(2, f"--key-file {path}: expected 64 hex digits (and a newline) or exactly 32 raw bytes")


def autopilot_heartbeat(conn, until, signed=None):
    """The next HEARTBEAT of an autopilot (not a GCS) before `until`: signed with our key when
    `signed`, unsigned when not, either when None; None when none came."""
    while time.monotonic() < until:
        msg = conn.recv_match(type="HEARTBEAT", blocking=True, timeout=0.5)
        if msg is None or msg.type == mavutil.mavlink.MAV_TYPE_GCS:
            continue
        if msg.autopilot == mavutil.mavlink.MAV_AUTOPILOT_INVALID:
            continue
        if signed is None or bool(getattr(msg, "_signed", False)) == signed:
            return msg
    return None


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--connect", required=True, help="pymavlink connection, e.g. tcp:127.0.0.1:5760 or /dev/ttyACM0")
    parser.add_argument("--baud", type=int, default=115200, help="serial baud rate (default 115200)")
    what = parser.add_mutually_exclusive_group(required=True)
    what.add_argument("--key-file", help="the key to load, e.g. key (as tdma-run's --mavlink-key-file)")
    what.add_argument("--disable", action="store_true", help="turn signing off (an all-zero key)")
    parser.add_argument("--timeout", type=float, default=30.0, help="give up after this many s (default 30)")
    parser.add_argument("--source-system", type=int, default=255, help="our system id (default 255)")
    args = parser.parse_args()
    key = bytes(32) if args.disable else read_key(args.key_file)

    until = time.monotonic() + args.timeout
    conn = None
    while conn is None:
        try:
            conn = mavutil.mavlink_connection(
                args.connect, baud=args.baud, source_system=args.source_system, source_component=190, autoreconnect=False
            )
        except OSError as error:
            if time.monotonic() > until:
                fail(1, f"{args.connect}: {error}")
            time.sleep(0.5)
    first = autopilot_heartbeat(conn, until)
    if first is None:
        fail(1, f"{args.connect}: no autopilot HEARTBEAT within {args.timeout:g} s")
    system, component = first.get_srcSystem(), first.get_srcComponent()
    initial = 0 if args.disable else int((time.time() - EPOCH_2015_S) * 100_000)
    if not args.disable:
        conn.setup_signing(key, sign_outgoing=True, initial_timestamp=initial)
    answered = None
    while answered is None and time.monotonic() < until:
        conn.mav.setup_signing_send(system, component, key, initial)
        answered = autopilot_heartbeat(conn, min(until, time.monotonic() + 2.0), signed=not args.disable)
    if answered is None:
        state = "unsigned" if args.disable else "signed with the key"
        fail(1, f"system {system} component {component} sent no HEARTBEAT {state} within {args.timeout:g} s")
    if args.disable:
        print(f"mavlink-setup-signing: system {system} component {component}: signing off", file=sys.stderr)
    else:
        print(
            f"mavlink-setup-signing: system {system} component {component} signs with the key "
            f"and refuses unsigned messages (but on SERIAL0/USB)",
            file=sys.stderr,
        )


if __name__ == "__main__":
    main()
