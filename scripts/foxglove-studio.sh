#!/usr/bin/env bash
# Foxglove Studio 1.48.0, unmodified, against tdma-run's live view and its --mcap logs (issue 28).
#
# Studio is the prebuilt bundle npm ships in @foxglove/studio-base 1.48.0 (assets/index.js, a
# UMD module with React 17 external), rendered by scripts/foxglove-studio/{index.html,app.js}
# as Studio's web app renders it, in headless Chromium (Debian `chromium`) driven by Playwright
# (PyPI) with executable_path: no browser download, no bundler, no change to Studio. Not a CI
# test: the first run downloads the 36 MB package (179 MB unpacked) from npm. What this script
# shares with scripts/foxglove-studio-map.sh (octo-delta's live map in Studio) is in
# scripts/foxglove-studio/common.sh.
#
# Three sessions, each with --foxglove and --mcap:
#  - sim: `tdma-run --sim --pace 1` (both ends in one process, so frames have a delay_ms);
#  - operator: `tdma-run --role operator` over `link-sim --pty` (the S100 model the tests use)
#    to a ROV standing still (an all-zero joystick script);
#  - network: `tdma-run --scenario scenarios/relay-rf.json --pace 1`, on its own layout
#    (layout-network.json: both vehicles in 3D, vehicle 2's image, /network/frames.delay_ms).
# The sim and the operator hold a control token (`tdma-run --new-foxglove-token`), which the URL
# Studio opens carries (`ws://...:PORT/?token=...`); the operator is first opened without it,
# where Studio views, its GoTo is refused (Studio lists the refusal) and nothing is sent; the
# network is view only.
# Studio opens each live (`?ds=foxglove-websocket&ds.url=ws://...`) on a layout with 3D, Image,
# Plot (/link/frames.delay_ms), Log (/session/log, /link/log), Publish and Teleop, watches,
# sends the Publish panel's GoTo (not to the network: its orders are its waypoints) and waits
# for `order N acknowledged` on /session/log; then the session is stopped as by Ctrl-C (it keeps
# its outputs). Then Studio opens the logs: as remote files (`?ds=remote-file`, HTTP ranges from
# a loopback server) and the operator's as a local file too.
# Each step fails on any entry of Studio's Problems list, any error in a panel's settings, any
# console or page error, and panels left blank (scripts/foxglove-studio/check.py says which);
# then each session's --metrics must count the GoTo acknowledged, and tdma-run must have warned
# of nothing Studio sent but the 3D panel's three channels. Last, a control: a log with
# a schema Studio refuses (bad_log.py) must fail the same check with Studio's message.
#
# Usage: scripts/foxglove-studio.sh [OUT_DIR]   (default target/foxglove-studio/out)
# Environment: STUDIO_CACHE (where npm installs Studio; default target/foxglove-studio/cache,
#              kept between runs), BIN (the directory of tdma-run and link-sim; default: a
#              debug build of both), SESSION_MAX_S (a bound on each session, default 1200 s;
#              each is stopped by SIGINT once its live check is done), KEEP=1 keeps the work
#              directory.
# Needs: node and npm, python3 with playwright and mcap (pip install playwright mcap),
# /usr/bin/chromium (apt-get install chromium).
# Exit 0 when every check passes, 1 when one fails, 2 when a check could not be made.
set -euo pipefail
cd "$(dirname "$0")/.."

me=foxglove-studio
out=${1:-target/foxglove-studio/out}
cache=${STUDIO_CACHE:-target/foxglove-studio/cache}
# Each session runs until its live check is done, then is stopped as by Ctrl-C (which keeps its
# outputs); this bounds it if the script dies first.
seconds_max=${SESSION_MAX_S:-1200}
here=scripts/foxglove-studio
# shellcheck source=foxglove-studio/common.sh
. "$here/common.sh"
need_tools debug tdma-run link-sim

mkdir -p "$work/data"
"$BIN/tdma-run" --new-foxglove-token "$work/foxglove.token" 2>/dev/null \
  || fail_setup "tdma-run --new-foxglove-token failed"
token=$(cat "$work/foxglove.token")
# Session 1: a simulation at real time (both ends in one process: frames have a delay).
sim_port=$(free_port)
"$BIN/tdma-run" --sim --pace 1 --duration "$seconds_max" --foxglove "127.0.0.1:$sim_port" \
  --foxglove-token-file "$work/foxglove.token" \
  --mcap "$work/data/sim.mcap" --metrics "$work/sim.json" 2>"$work/sim.err" &
sim=$!
pids+=($sim)
wait_for_line "$work/sim.err" "Foxglove: ws://" 20 "the simulation's live view" "$sim"

# Session 2: an operator over link-sim's pseudo-terminals, A for the operator, B for the ROV.
start_link_sim --model s100 --bitrate-bps 9600 --intrinsic-delay-ms 20 --jitter-ms 2 \
  --half-duplex false
printf 't_s,vx,vy,vz,vyaw\n0,0,0,0,0\n' >"$work/still.csv"
"$BIN/tdma-run" --role rov --port "$side_b" --duration "$seconds_max" --image-size 400 \
  --metrics "$work/rov.json" 2>"$work/rov.err" &
rov=$!
pids+=($rov)
op_port=$(free_port)
"$BIN/tdma-run" --role operator --port "$side_a" --ipg 150 --duration "$seconds_max" \
  --image-size 400 --script "$work/still.csv" --foxglove "127.0.0.1:$op_port" \
  --foxglove-token-file "$work/foxglove.token" \
  --mcap "$work/data/operator.mcap" --metrics "$work/op.json" 2>"$work/op.err" &
operator=$!
pids+=($operator)
wait_for_line "$work/op.err" "Foxglove: ws://" 20 "the operator's live view" "$operator"

# Session 3: a network (scenarios/relay-rf.json: an operator, a relay, a far vehicle) at real
# time: every vehicle under /vehicle/N/, and /network/frames.
net_port=$(free_port)
"$BIN/tdma-run" --scenario scenarios/relay-rf.json --pace 1 --duration "$seconds_max" \
  --foxglove "127.0.0.1:$net_port" --mcap "$work/data/network.mcap" 2>"$work/net.err" &
network=$!
pids+=($network)
wait_for_line "$work/net.err" "Foxglove: ws://" 20 "the network's live view" "$network"

start_page_server
live_topics=/rov/pose,/tf,/camera/image,/link/frames,/session/log
file_topics=/rov/pose,/tf,/camera/image,/link/frames
check sim-live --ws "ws://127.0.0.1:$sim_port/?token=$token" --publish --expect "$live_topics" --expect-delay
stop "$sim" "$work/sim.err" "the simulation"
# Without the token Studio views, and its GoTo is refused (a problem it lists); with it, drives.
# (/session/log is not expected before that: no order has gone out yet.)
check operator-view --ws "ws://127.0.0.1:$op_port" --publish-refused --expect "$file_topics"
check operator-live --ws "ws://127.0.0.1:$op_port/?token=$token" --publish --expect "$live_topics"
stop "$operator" "$work/op.err" "the operator"
stop "$rov" "$work/rov.err" "the ROV"
net_topics=/vehicle/1/rov/pose,/vehicle/2/rov/pose,/vehicle/1/tf,/network/frames
check network-live --layout layout-network.json --ws "ws://127.0.0.1:$net_port" \
  --expect "$net_topics" --expect-delay
stop "$network" "$work/net.err" "the network"
for session in sim op; do
  # Exactly one GoTo went out: the one sent with the token.
  python3 -c '
import json, sys
metrics = json.load(open(sys.argv[2]))
sent, acked = metrics.get("orders_sent", 0), metrics.get("orders_acknowledged", 0)
print(f"{sys.argv[1]}: {sent} order(s) sent, {acked} acknowledged (its --metrics)")
sys.exit(0 if acked >= 1 and sent == 1 else 1)
' "$session" "$work/$session.json" || status=1
done
for session in sim op net; do
  # The 3D panel's three channels are refused (docs/tdma-foxglove.md); the Publish and Teleop
  # panels' are not (Studio holds the token), and nothing Studio sends is skipped. The network
  # takes no orders: Studio's publishing is refused there, once.
  warned_of_studio "$session" "$work/$session.err" "$token" \
    "(/move_base_simple/goal): refused" "(/clicked_point): refused" "(/initialpose): refused" \
    "publishing refused: this live view takes no orders" \
    "publishing refused: its URL has no control token"
done

check sim-file --remote-file "${studio}data/sim.mcap" --expect "$file_topics" \
  --absent /session/log --expect-delay
check operator-file --remote-file "${studio}data/operator.mcap" --expect "$file_topics" \
  --absent /session/log
check operator-local-file --local-file "$work/data/operator.mcap" --expect "$file_topics" \
  --absent /session/log
check network-file --layout layout-network.json --remote-file "${studio}data/network.mcap" \
  --expect "$net_topics" --expect-delay
# The control: a log with a schema Studio refuses must fail, with Studio's own message.
python3 "$here/bad_log.py" "$work/data/control.mcap"
control=0
python3 "$here/check.py" control --studio "$studio" --out "$work/control" \
  --remote-file "${studio}data/control.mcap" --settle-s 2 >"$work/control.out" 2>&1 || control=$?
refused='problem: .*Unsupported type \["number","null"\] for t_sent_s'
if [ "$control" = 1 ] && grep -q "$refused" "$work/control.out"; then
  echo "control: a log with a type array in a schema fails, as it must:" \
    "$(grep -m1 -o 'Unsupported type \[[^]]*\] for t_sent_s' "$work/control.out" | head -1)"
else
  echo "control: a log with a type array in a schema did not fail with Studio's message" \
    "(exit $control):"
  cat "$work/control.out"
  status=1
fi
finish "live and from the logs"
