#!/usr/bin/env python3
"""A stand-in ArduSub written with pymavlink, independent of the Rust `mavlink` crate.

It speaks MAVLink 2 (ardupilotmega dialect) as system 1 component 1, a MAV_TYPE_SUBMARINE on
MAV_AUTOPILOT_ARDUPILOTMEGA, and simulates motion simply:
- HEARTBEAT at 1 Hz (armed flag, ArduSub custom mode), LOCAL_POSITION_NED and ATTITUDE at 10 Hz;
- COMMAND_LONG answered with COMMAND_ACK: MAV_CMD_COMPONENT_ARM_DISARM (param1),
  MAV_CMD_DO_SET_MODE (param2 = ArduSub custom mode), MAV_CMD_SET_MESSAGE_INTERVAL;
- armed in a stick mode: MANUAL_CONTROL x, y (1000 = 1 m/s), r (1000 = 30 degrees/s) are body
  velocities and z is ArduSub's throttle (0..1000, 500 neutral, up positive: 0 = 0.5 m/s down);
- armed in GUIDED: goes to the last SET_POSITION_TARGET_LOCAL_NED at 0.5 m/s, turns to its yaw.
As ArduSub does, it takes MANUAL_CONTROL and commands only when addressed to it, setpoints only
in GUIDED. And as the real ArduSub SITL showed: no LOCAL_POSITION_NED, and GUIDED and POSHOLD
refused (MAV_RESULT_FAILED, STATUSTEXT "Mode change failed: GUIDED requires position"), until it
has a position (--position-after S; --no-position: never, like GPS1_TYPE 0); positively buoyant
(rises at 0.08 m/s to the surface unless ALT_HOLD, POSHOLD or GUIDED holds its depth); the GCS
failsafe (armed, a GCS once heard, then 5 s without its HEARTBEAT and MANUAL_CONTROL: disarmed).

With --key-file FILE (64 hex digits, or 32 raw bytes) it signs everything it sends (MAVLink 2
signing, pymavlink's) and takes only messages signed with that key, as ArduSub does once
SETUP_SIGNING gave it the key; what it refused is counted (bad_signatures). With --forgeries it
also sends, from its own address, every second: a LOCAL_POSITION_NED at (40, 40, 4) unsigned,
the same signed with another key, and a replay of its first signed LOCAL_POSITION_NED
(forgeries: how many of each were sent). With --key-behind S its signing clock starts S seconds
behind the wall clock (an autopilot without a clock of its own, on the time it last saved) and,
as ArduPilot's and pymavlink's do, catches up with the newest signed timestamp it accepts.

At exit (after --seconds, or on SIGTERM/SIGINT) it writes what it saw as JSON to --report:
armed (ever), armed_now, modes (every mode switched to), max_manual_x, manual_controls,
last_manual, setpoints ([x, y, z, yaw]), setpoint_frame, commands (names), gcs ([system,
component] of the GCS heartbeats), gcs_heartbeats, position ([x, y, z] NED m), heading_deg.

Usage: ardusub.py (--connect udpout:HOST:PORT | --listen udpin:HOST:PORT | tcp:HOST:PORT ...)
                  --report FILE [--seconds N] [--deny-arm] [--start X,Y,Z]
                  [--position-after S | --no-position]
                  [--key-file FILE [--forgeries] [--key-behind S]]
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

MANUAL, STABILIZE, ALT_HOLD, POSHOLD, GUIDED = 19, 0, 2, 16, 4
MODES = {MANUAL, STABILIZE, ALT_HOLD, POSHOLD, GUIDED}
DEPTH_HOLDING = {ALT_HOLD, POSHOLD, GUIDED}
BUOYANT_RISE_MPS = 0.08
GCS_FAILSAFE_S = 5.0


def wrap_pi(angle):
    return (angle + math.pi) % (2 * math.pi) - math.pi


class Sub:
    def __init__(self, conn, deny_arm, start, position_after=0.0):
        self.conn = conn
        self.mav = conn.mav
        self.deny_arm = deny_arm
        self.armed = False
        self.ever_armed = False
        self.mode = MANUAL
        self.modes = []
        self.position = list(start)
        self.yaw = 0.0
        self.velocity = [0.0, 0.0, 0.0]
        self.yaw_rate = 0.0
        self.sticks = None  # (x, y, z, r, time)
        self.target = None  # (x, y, z, yaw)
        self.max_manual_x = None
        self.manual_controls = 0
        self.last_manual = None
        self.setpoints = []
        self.setpoint_frame = None
        self.commands = []
        self.gcs = None
        self.gcs_heartbeats = 0
        self.started = time.monotonic()
        self.position_after = position_after
        self.gcs_heard = None
        self.failsafes = 0
        self.modes_refused = 0
        self.bad_signatures = 0
        self.forgeries = 0
        self.first_position = None

    def has_position(self):
        return self.position_after is not None and time.monotonic() - self.started >= self.position_after

    def boot_ms(self):
        return int((time.monotonic() - self.started) * 1000) & 0xFFFFFFFF

    def handle(self, msg):
        kind = msg.get_type()
        me = self.mav.srcSystem
        if kind == "HEARTBEAT" and msg.type == mavutil.mavlink.MAV_TYPE_GCS:
            self.gcs_heartbeats += 1
            self.gcs_heard = time.monotonic()
            self.gcs = [msg.get_srcSystem(), msg.get_srcComponent()]
        elif kind == "MANUAL_CONTROL" and msg.target == me:
            self.manual_controls += 1
            self.gcs_heard = time.monotonic()
            self.max_manual_x = msg.x if self.max_manual_x is None else max(self.max_manual_x, msg.x)
            self.last_manual = [msg.x, msg.y, msg.z, msg.r]
            self.sticks = (msg.x, msg.y, msg.z, msg.r, time.monotonic())
        elif kind == "SET_POSITION_TARGET_LOCAL_NED" and msg.target_system == me:
            self.setpoints.append([msg.x, msg.y, msg.z, msg.yaw])
            self.setpoint_frame = msg.coordinate_frame
            if self.mode == GUIDED and msg.coordinate_frame == mavutil.mavlink.MAV_FRAME_LOCAL_NED:
                self.target = (msg.x, msg.y, msg.z, msg.yaw)
        elif kind == "COMMAND_LONG" and msg.target_system == me:
            name = mavutil.mavlink.enums["MAV_CMD"][msg.command].name
            self.commands.append(name)
            result = mavutil.mavlink.MAV_RESULT_UNSUPPORTED
            if msg.command == mavutil.mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
                if self.deny_arm:
                    result = mavutil.mavlink.MAV_RESULT_DENIED
                else:
                    self.armed = msg.param1 > 0.5
                    self.ever_armed = self.ever_armed or self.armed
                    result = mavutil.mavlink.MAV_RESULT_ACCEPTED
            elif msg.command == mavutil.mavlink.MAV_CMD_DO_SET_MODE:
                mode = int(msg.param2)
                if mode in (GUIDED, POSHOLD) and not self.has_position():
                    self.modes_refused += 1
                    name = "GUIDED" if mode == GUIDED else "POSHOLD"
                    text = ("Mode change failed: %s requires position" % name).encode()
                    self.mav.statustext_send(mavutil.mavlink.MAV_SEVERITY_WARNING, text)
                    result = mavutil.mavlink.MAV_RESULT_FAILED
                elif mode in MODES:
                    if mode != self.mode:
                        self.modes.append(mode)
                        self.target = None
                    self.mode = mode
                    result = mavutil.mavlink.MAV_RESULT_ACCEPTED
                else:
                    result = mavutil.mavlink.MAV_RESULT_DENIED
            elif msg.command == mavutil.mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
                result = mavutil.mavlink.MAV_RESULT_ACCEPTED
            self.mav.command_ack_send(msg.command, result)

    def tick(self, dt):
        self.velocity = [0.0, 0.0, 0.0]
        self.yaw_rate = 0.0
        if self.armed and self.gcs_heard is not None and time.monotonic() - self.gcs_heard >= GCS_FAILSAFE_S:
            self.armed = False
            self.failsafes += 1
            self.gcs_heard = None
        if self.armed and self.mode == GUIDED and self.target is not None:
            x, y, z, yaw = self.target
            error = [x - self.position[0], y - self.position[1], z - self.position[2]]
            distance = math.sqrt(sum(e * e for e in error))
            if distance > 1e-9:
                speed = min(0.5, distance / dt)
                self.velocity = [e / distance * speed for e in error]
            limit = math.radians(30)
            self.yaw_rate = max(-limit, min(limit, wrap_pi(yaw - self.yaw) / dt))
        elif self.armed and self.sticks is not None and time.monotonic() - self.sticks[4] < 1.0:
            x, y, z, r, _ = self.sticks
            surge, sway = x / 1000.0, y / 1000.0
            c, s = math.cos(self.yaw), math.sin(self.yaw)
            self.velocity = [surge * c - sway * s, surge * s + sway * c, (500 - z) / 500.0 * 0.5]
            self.yaw_rate = r / 1000.0 * math.radians(30)
        if not (self.armed and self.mode in DEPTH_HOLDING):
            self.velocity[2] -= BUOYANT_RISE_MPS
        for k in range(3):
            self.position[k] += self.velocity[k] * dt
        self.position[2] = max(0.0, self.position[2])
        self.yaw = wrap_pi(self.yaw + self.yaw_rate * dt)

    def send_heartbeat(self):
        base = mavutil.mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if self.armed:
            base |= mavutil.mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        self.mav.heartbeat_send(
            mavutil.mavlink.MAV_TYPE_SUBMARINE,
            mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
            base,
            self.mode,
            mavutil.mavlink.MAV_STATE_ACTIVE,
        )

    def send_state(self):
        x, y, z = self.position
        vx, vy, vz = self.velocity
        if self.has_position():
            msg = self.mav.local_position_ned_encode(self.boot_ms(), x, y, z, vx, vy, vz)
            self.mav.send(msg)
            if self.first_position is None:
                self.first_position = bytes(msg.get_msgbuf())
        self.mav.attitude_send(self.boot_ms(), 0.0, 0.0, self.yaw, 0.0, 0.0, self.yaw_rate)

    def send_forgeries(self):
        """A LOCAL_POSITION_NED at (40, 40, 4) unsigned and signed with another key, and a
        replay of the first signed one (needs signing)."""
        signing = self.mav.signing
        fake = self.mav.local_position_ned_encode(self.boot_ms(), 40.0, 40.0, 4.0, 0, 0, 0)
        signing.sign_outgoing = False
        self.mav.send(fake)
        signing.sign_outgoing = True
        key = signing.secret_key
        signing.secret_key = bytes(32 * [0x5A])
        self.mav.send(self.mav.local_position_ned_encode(self.boot_ms(), 40.0, 40.0, 4.0, 0, 0, 0))
        signing.secret_key = key
        if self.first_position is not None:
            self.conn.write(self.first_position)
        self.forgeries += 1

    def report(self):
        return {
            "armed": self.ever_armed,
            "armed_now": self.armed,
            "modes": self.modes,
            "mode": self.mode,
            "max_manual_x": self.max_manual_x,
            "manual_controls": self.manual_controls,
            "last_manual": self.last_manual,
            "setpoints": self.setpoints,
            "setpoint_frame": self.setpoint_frame,
            "commands": self.commands,
            "gcs": self.gcs,
            "gcs_heartbeats": self.gcs_heartbeats,
            "position": self.position,
            "heading_deg": math.degrees(self.yaw) % 360.0,
            "modes_refused": self.modes_refused,
            "failsafes": self.failsafes,
            "bad_signatures": self.bad_signatures,
            "forgeries": self.forgeries,
        }


def read_key(path):
    """A key file: 64 hex digits (and a newline), or 32 raw bytes."""
    data = open(path, "rb").read()
    if len(data) == 32:
        return data
    return bytes.fromhex(data.decode().strip())


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    where = parser.add_mutually_exclusive_group(required=True)
    where.add_argument("--connect", help="pymavlink connection string, e.g. udpout:127.0.0.1:14550")
    where.add_argument("--listen", help="pymavlink connection string, e.g. udpin:127.0.0.1:14551")
    parser.add_argument("--report", required=True, help="JSON file written at exit")
    parser.add_argument("--seconds", type=float, default=3600.0, help="run this long, then exit")
    parser.add_argument("--deny-arm", action="store_true", help="answer arm requests with DENIED")
    parser.add_argument("--start", default="0,0,0", help="start position X,Y,Z (NED m)")
    fix = parser.add_mutually_exclusive_group()
    fix.add_argument("--position-after", type=float, default=0.0, help="a position this many s after start")
    fix.add_argument("--no-position", action="store_true", help="never a position (GPS1_TYPE 0)")
    parser.add_argument("--key-file", help="sign with this key, take only what it signed")
    parser.add_argument("--forgeries", action="store_true", help="also send forged positions (with --key-file)")
    parser.add_argument("--key-behind", type=float, default=0.0, help="start the signing clock this many s behind")
    args = parser.parse_args()
    if args.forgeries and not args.key_file:
        parser.error("--forgeries needs --key-file")
    start = [float(v) for v in args.start.split(",")]
    if len(start) != 3:
        parser.error("--start: expected X,Y,Z")

    conn = mavutil.mavlink_connection(
        args.connect or args.listen,
        source_system=1,
        source_component=1,
        dialect="ardupilotmega",
        autoreconnect=True,
    )
    if args.key_file:
        initial = int((time.time() - 1420070400 - args.key_behind) * 100000)
        conn.setup_signing(read_key(args.key_file), sign_outgoing=True, initial_timestamp=initial)
    sub = Sub(conn, args.deny_arm, start, None if args.no_position else args.position_after)
    stopping = []
    signal.signal(signal.SIGTERM, lambda *_: stopping.append(1))
    signal.signal(signal.SIGINT, lambda *_: stopping.append(1))

    deadline = time.monotonic() + args.seconds
    next_tick = time.monotonic()
    next_heartbeat = next_tick
    while not stopping and time.monotonic() < deadline:
        now = time.monotonic()
        if now >= next_tick:
            next_tick += 0.1
            sub.tick(0.1)
            if now >= next_heartbeat:
                next_heartbeat += 1.0
                sub.send_heartbeat()
                if args.forgeries:
                    sub.send_forgeries()
            sub.send_state()
        try:
            msg = conn.recv_match(blocking=True, timeout=max(0.0, min(0.05, next_tick - time.monotonic())))
        except (ConnectionError, OSError):
            msg = None
        if msg is not None and msg.get_type() == "BAD_DATA" and "signature" in str(msg.reason):
            sub.bad_signatures += 1
        elif msg is not None and msg.get_type() != "BAD_DATA":
            sub.handle(msg)

    with open(args.report, "w") as out:
        json.dump(sub.report(), out)
    print("ardusub.py: report written to %s" % args.report, file=sys.stderr)


if __name__ == "__main__":
    main()
