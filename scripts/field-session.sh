#!/usr/bin/env bash
# The field bar of issue 16, as a scenario: operator <-> link-sim --model s100 --pty <-> ROV <->
# a pymavlink ArduSub stand-in over UDP, 85 s, orders fed live through a FIFO (a half-stick
# forward velocity, then a goto), the operator's --telemetry, and a Foxglove client on the
# operator's --foxglove server. Then the virtual-time 1-hour session, median of 5 whole runs.
# Prints a pass/fail table; exit 0 when every check passes, 1 otherwise, 2 on a set-up failure.
#
# Usage: scripts/field-session.sh [SECONDS]   (SECONDS: the operator's session, default 85)
# Environment: BIN (the directory of tdma-run and link-sim; default: build target/release),
#              KEEP=1 keeps the work directory and says where.
set -euo pipefail
cd "$(dirname "$0")/.."

seconds=${1:-85}
if [ -z "${BIN:-}" ]; then
  cargo build --release --quiet --bin tdma-run --bin link-sim
  BIN=target/release
fi
for tool in "$BIN/tdma-run" "$BIN/link-sim"; do
  [ -x "$tool" ] || { echo "field-session: $tool: not built" >&2; exit 2; }
done
python3 -c 'import pymavlink' 2>/dev/null || { echo "field-session: pip install pymavlink" >&2; exit 2; }
[ -f tests/foxglove/client.py ] || { echo "field-session: tests/foxglove/client.py missing" >&2; exit 2; }

work=$(mktemp -d)
pids=()
cleanup() {
  for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done
  wait 2>/dev/null || true
  if [ "${KEEP:-0}" = 1 ]; then echo "field-session: kept $work" >&2; else rm -rf "$work"; fi
}
trap cleanup EXIT

free_port() { # a free port of the kind given (udp or tcp), on 127.0.0.1
  python3 -c "import socket,sys; s=socket.socket(socket.AF_INET, socket.SOCK_DGRAM if sys.argv[1]=='udp' else socket.SOCK_STREAM); s.bind(('127.0.0.1',0)); print(s.getsockname()[1])" "$1"
}
mav_port=$(free_port udp)
fox_port=$(free_port tcp)

# The link: two pseudo-terminals, A for the operator, B for the ROV.
"$BIN/link-sim" --model s100 --pty >"$work/link.out" 2>"$work/link.err" &
pids+=($!)
for _ in $(seq 50); do [ "$(wc -l <"$work/link.out")" -ge 2 ] && break; sleep 0.1; done
side_a=$(sed -n 1p "$work/link.out")
side_b=$(sed -n 2p "$work/link.out")
[ -n "$side_a" ] && [ -n "$side_b" ] || { echo "field-session: link-sim gave no pseudo-terminals" >&2; exit 2; }

# The autopilot, sending to the ROV end's udpin port; its report is written when it is stopped.
python3 tests/mavlink/ardusub.py --connect "udpout:127.0.0.1:$mav_port" \
  --report "$work/autopilot.json" --seconds $((seconds + 60)) 2>"$work/autopilot.err" &
autopilot=$!
pids+=($autopilot)

"$BIN/tdma-run" --role rov --port "$side_b" --vehicle "mavlink:udpin:127.0.0.1:$mav_port" \
  --duration $((seconds + 5)) --metrics "$work/rov.json" 2>"$work/rov.err" &
rov=$!
pids+=($rov)
sleep 0.5

mkfifo -m 600 "$work/orders"
"$BIN/tdma-run" --role operator --port "$side_a" --duration "$seconds" \
  --orders "$work/orders" --telemetry "$work/telemetry.jsonl" \
  --foxglove "127.0.0.1:$fox_port" --images-out "$work/images" \
  --metrics "$work/operator.json" 2>"$work/operator.err" &
operator=$!
pids+=($operator)

# Orders as an operator types them: half stick forward, then stop and go to a point.
goal_x=3 goal_y=2 goal_z=1 goal_heading=90
{
  sleep 3
  echo '{"type":"velocity","vx":64,"vy":0,"vz":0,"vyaw":0,"arm":true,"disarm":false,"nav":"manual"}'
  sleep 12
  echo '{"type":"velocity","vx":0,"vy":0,"vz":0,"vyaw":0,"arm":true,"disarm":false,"nav":"manual"}'
  echo "{\"type\":\"goto\",\"x_cm\":$((goal_x * 100)),\"y_cm\":$((goal_y * 100)),\"z_cm\":$((goal_z * 100)),\"heading_deg\":$goal_heading}"
  sleep $((seconds))
} >"$work/orders" &
pids+=($!)

sleep 4
python3 tests/foxglove/client.py --url "ws://127.0.0.1:$fox_port" --connect-within 10 \
  --topics /rov/pose,/camera/image \
  --seconds $((seconds - 15)) --out "$work/foxglove.json" 2>"$work/foxglove.err" &
pids+=($!)

operator_status=0
wait "$operator" || operator_status=$?
rov_status=0
wait "$rov" || rov_status=$?
kill -TERM "$autopilot" 2>/dev/null || true
wait "$autopilot" 2>/dev/null || true
wait "${pids[-1]}" 2>/dev/null || true # the Foxglove client

# The virtual-time 1-hour session, built-in images: median of 5 whole-process runs.
virtual_s=$(python3 - "$BIN/tdma-run" <<'EOF'
import statistics, subprocess, sys, time
times = []
for _ in range(5):
    start = time.monotonic()
    done = subprocess.run([sys.argv[1], "--duration", "3600"],
                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    times.append(time.monotonic() - start if done.returncode == 0 else float("inf"))
print("%.3f" % statistics.median(times))
EOF
)

python3 - "$work" "$operator_status" "$rov_status" "$virtual_s" "$goal_x" "$goal_y" "$goal_z" <<'EOF'
import json, math, os, sys

work, operator_status, rov_status, virtual_s = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), float(sys.argv[4])
goal = [float(v) for v in sys.argv[5:8]]

def load(name, default=None):
    try:
        with open(os.path.join(work, name)) as f:
            return json.load(f)
    except (OSError, ValueError):
        return default

autopilot = load("autopilot.json", {})
operator = load("operator.json", {})
foxglove = load("foxglove.json", {})
telemetry = []
try:
    with open(os.path.join(work, "telemetry.jsonl")) as f:
        for line in f:
            try:
                telemetry.append(json.loads(line))
            except ValueError:
                pass
except OSError:
    pass
statuses = [t for t in telemetry if t.get("type") == "rov" and "x_cm" in t]
order_states = [t.get("state") for t in telemetry if t.get("type") == "order"]

rows = []
def check(name, ok, detail):
    rows.append((name, bool(ok), detail))

check("both ends exit 0", operator_status == 0 and rov_status == 0,
      "operator %d, rov %d" % (operator_status, rov_status))
check("autopilot armed", autopilot.get("armed") is True, "armed=%s" % autopilot.get("armed"))
x = autopilot.get("max_manual_x")
check("MANUAL_CONTROL x ~ 500 at half stick", x is not None and 480 <= x <= 520, "max x=%s" % x)
modes = autopilot.get("modes", [])
check("GUIDED for the goto", 4 in modes, "modes=%s" % modes)
setpoints = autopilot.get("setpoints") or [[None] * 4]
last = setpoints[-1]
near = all(v is not None and abs(v - g) < 1e-3 for v, g in zip(last[:3], goal))
check("the goto's setpoint (MAV_FRAME_LOCAL_NED)", near and autopilot.get("setpoint_frame") == 1,
      "last=%s frame=%s" % (last, autopilot.get("setpoint_frame")))
position = autopilot.get("position")
if statuses and position:
    s = statuses[-1]
    seen = [s["x_cm"] / 100, s["y_cm"] / 100, s["z_cm"] / 100]
    error = math.dist(seen, position)
    check("last telemetry status within 0.3 m of the autopilot", error <= 0.3,
          "%.3f m (%s vs %s)" % (error, seen, [round(p, 3) for p in position]))
else:
    check("last telemetry status within 0.3 m of the autopilot", False,
          "%d statuses, autopilot position %s" % (len(statuses), position))
sent, acked = operator.get("orders_sent"), operator.get("orders_acknowledged")
check("orders acknowledged", bool(sent) and sent == acked and "acknowledged" in order_states,
      "sent %s, acknowledged %s, telemetry states %s" % (sent, acked, sorted(set(order_states))))
images = operator.get("images_completed") or 0
check("images complete", images >= 1, "%d images" % images)
poses = foxglove.get("/rov/pose", 0)
check("Foxglove client receives pose messages", poses > 0,
      "/rov/pose %s, /camera/image %s" % (poses, foxglove.get("/camera/image", 0)))
check("virtual-time 1-hour session under 1 s", virtual_s < 1.0, "median %.3f s of 5" % virtual_s)

width = max(len(r[0]) for r in rows)
for name, ok, detail in rows:
    print("%-*s  %s  %s" % (width, name, "PASS" if ok else "FAIL", detail))
sys.exit(0 if all(ok for _, ok, _ in rows) else 1)
EOF
