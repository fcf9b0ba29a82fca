#!/usr/bin/env python3
"""Watches an autopilot on a MAVLink port of its own (ArduSub SITL's SERIAL1, TCP 5762 + 10 x
INSTANCE) without speaking to it, and writes what it reports as JSON lines, flushed as they come:

  {"t": WALL_S, "boot_s": S, "type": "pos", "x": M, "y": M, "z": M}      LOCAL_POSITION_NED
  {"t": WALL_S, "boot_s": S, "type": "att", "yaw_deg": D}                ATTITUDE, at most 2 Hz
  {"t": WALL_S, "boot_s": S, "type": "mode", "armed": B, "mode": N}      HEARTBEAT, on a change
  {"t": WALL_S, "boot_s": S, "type": "text", "severity": N, "text": T}   STATUSTEXT
  {"t": WALL_S, "boot_s": S, "type": "sim", "n": M, "e": M}   SIMSTATE, at most 2 Hz
  {"t": WALL_S, "boot_s": S, "type": "boot"}                            once a second (SYSTEM_TIME)

SIMSTATE is SITL's own truth (the simulated vehicle's place, in metres north and east of the
first SIMSTATE), there before the EKF has a position.

t is the wall clock (time.time()), boot_s the autopilot's own time since boot. It listens as
system 254 and never sends: ArduSub's GCS failsafe counts only its GCS's system (255).
Ends on SIGTERM or SIGINT, or when the port closes.

Usage: sitl_watch.py --connect tcp:127.0.0.1:5772 --out watch.jsonl
"""

import argparse
import json
import math
import os
import signal
import sys
import time

os.environ["MAVLINK20"] = "1"
from pymavlink import mavutil  # noqa: E402


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--connect", required=True, help="e.g. tcp:127.0.0.1:5772")
    parser.add_argument("--out", required=True, help="the JSON lines file to write")
    args = parser.parse_args()
    stop = []
    signal.signal(signal.SIGTERM, lambda *_: stop.append(1))
    signal.signal(signal.SIGINT, lambda *_: stop.append(1))
    conn = None
    deadline = time.monotonic() + 30
    while conn is None:
        try:
            conn = mavutil.mavlink_connection(args.connect, source_system=254, autoreconnect=False)
        except OSError as error:
            if time.monotonic() > deadline or stop:
                print(f"sitl_watch: {args.connect}: {error}", file=sys.stderr)
                sys.exit(2)
            time.sleep(0.2)
    last_mode = None
    last_att = 0.0
    last_boot = 0.0
    last_sim = None
    sim_origin = None
    with open(args.out, "w", encoding="utf-8") as out:

        def write(kind, boot_s, **fields):
            out.write(json.dumps({"t": time.time(), "boot_s": boot_s, "type": kind, **fields}) + "\n")
            out.flush()

        while not stop:
            try:
                msg = conn.recv_match(blocking=True, timeout=0.5)
            except (OSError, ConnectionError):
                break
            if msg is None or msg.get_srcComponent() != 1:
                continue
            kind = msg.get_type()
            if kind == "LOCAL_POSITION_NED":
                write("pos", msg.time_boot_ms / 1000, x=msg.x, y=msg.y, z=msg.z)
            elif kind == "ATTITUDE":
                boot_s = msg.time_boot_ms / 1000
                if boot_s - last_att >= 0.5:
                    last_att = boot_s
                    write("att", boot_s, yaw_deg=math.degrees(msg.yaw) % 360)
            elif kind == "HEARTBEAT" and msg.type == mavutil.mavlink.MAV_TYPE_SUBMARINE:
                armed = bool(msg.base_mode & mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED)
                if (armed, msg.custom_mode) != last_mode:
                    last_mode = (armed, msg.custom_mode)
                    write("mode", None, armed=armed, mode=msg.custom_mode)
            elif kind == "STATUSTEXT":
                write("text", None, severity=msg.severity, text=msg.text)
            elif kind == "SIMSTATE":
                now = time.monotonic()
                if last_sim is None or now - last_sim >= 0.5:
                    last_sim = now
                    lat, lng = msg.lat / 1e7, msg.lng / 1e7
                    if sim_origin is None:
                        sim_origin = (lat, lng)
                    north = (lat - sim_origin[0]) * 111319.49
                    east = (lng - sim_origin[1]) * 111319.49 * math.cos(math.radians(lat))
                    write("sim", None, n=north, e=east)
            elif kind == "SYSTEM_TIME":
                boot_s = msg.time_boot_ms / 1000
                if boot_s - last_boot >= 1.0:
                    last_boot = boot_s
                    write("boot", boot_s)


if __name__ == "__main__":
    main()
