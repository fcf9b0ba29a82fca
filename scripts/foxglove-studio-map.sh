#!/usr/bin/env bash
# Foxglove Studio 1.48.0, unmodified, against octo-delta's live map (`octo-delta view
# --foxglove`) and its --mcap log, with scripts/foxglove-studio.sh's harness (the same page,
# check.py, serve.py and scripts/foxglove-studio/common.sh; see there for how Studio is run), on
# a layout of its own (scripts/foxglove-studio/layout-map.json): a 3D panel showing
# /octo_delta/view (foxglove.SceneUpdate) and the vehicle /octo_delta/vehicle
# (foxglove.PoseInFrame) in frame map, and a Log panel on /octo_delta/log (foxglove.Log).
# Not a CI test (Studio comes from npm).
#
# The live map as README.md's "Live" section runs it on one machine: `link-sim --model
# satellite-up --reverse-model satellite-down --pty` for the satellite hop, `octo-delta synth
# --pace 0.5` recording the 80-scan survey (2 scans/s, 40 s), `octo-delta map --follow
# --exit-when-done` on end A and, on end B, `octo-delta view --foxglove 127.0.0.1:PORT
# --foxglove-token-file F -o view.ot --mcap view.mcap`. The token is what lets Studio connect
# without a problem: its 3D panel advertises three channels of its own (/move_base_simple/goal,
# /clicked_point, /initialpose) as it connects, and the view tells a client that may not
# publish (no token in its URL, or a view without a token file) `publishing refused: ...` in a
# status, which Studio lists as a problem; a client with the token is refused those three
# channels on the view's standard error only. Then:
#  - map-live: Studio opens ws://127.0.0.1:PORT/?token=... as the survey starts and watches it
#    all before it is read (while the map grows Studio redraws it whole at each message, which
#    in software WebGL holds the page for seconds at a time);
#  - the mapper must end by itself (everything acknowledged) and the view must have applied the
#    survey's last scan (79);
#  - map-view: Studio opens the view, idle now, without the token: it gets the whole map in one
#    SceneUpdate; its `publishing refused` problem is expected (listed as such), no other;
#  - the view is stopped by SIGINT (it writes -o and --mcap); it must have warned of nothing
#    Studio sent but the 3D panel's three channels, and that refusal;
#  - map-file and map-local-file: its --mcap log opened as a remote file (HTTP ranges) and as a
#    local file, seen near its end. There Studio reads each topic's latest message only, so the
#    3D panel shows the last SceneUpdate's blocks (scan 79's), not the whole map: playing the
#    log from its start would show it, but takes minutes in software WebGL (Studio reads at most
#    0.3 s of a log per frame and redraws the map whole each frame).
# Each fails (check.py) on any entry of Studio's Problems list, any error in a panel's settings,
# any console or page error, no 3D canvas, a 3D panel with less of the map's colours than
# expected (the whole map fills about 32 % of it, scan 79's blocks 0.3 %), and, live and from
# the log, a topic of the three with no message counted in the Topics list (not asked of
# map-view: on a view that sends nothing more, Studio's list may not count the one burst a late
# subscriber gets).
#
# Usage: scripts/foxglove-studio-map.sh [OUT_DIR]   (default target/foxglove-studio/map)
# Environment: STUDIO_CACHE (as foxglove-studio.sh's; point it at a cache a previous run left,
#              e.g. another checkout's target/foxglove-studio/cache, to download nothing), BIN
#              (the directory of octo-delta and link-sim; default: a release build of both),
#              KEEP=1 keeps the work directory.
# Needs what foxglove-studio.sh needs, and Pillow (pip install pillow). Takes about 3 minutes.
# Exit 0 when every check passes, 1 when one fails, 2 when a check could not be made.
set -euo pipefail
cd "$(dirname "$0")/.."

me=foxglove-studio-map
out=${1:-target/foxglove-studio/map}
cache=${STUDIO_CACHE:-target/foxglove-studio/cache}
here=scripts/foxglove-studio
# shellcheck source=foxglove-studio/common.sh
. "$here/common.sh"
need_tools release octo-delta link-sim
python3 -c 'import PIL' 2>/dev/null || fail_setup "python3 lacks Pillow (pip install pillow)"

# The control token, as `tdma-run --new-foxglove-token` writes one (yours, mode 0600).
(umask 077 && python3 -c 'import secrets; print(secrets.token_hex(32))' >"$work/foxglove.token")
token=$(cat "$work/foxglove.token")

start_link_sim --model satellite-up --reverse-model satellite-down
start_page_server
port=$(free_port)
"$BIN/octo-delta" view --port "$side_b" --foxglove "127.0.0.1:$port" \
  --foxglove-token-file "$work/foxglove.token" -o "$work/view.ot" --mcap "$work/data/view.mcap" \
  2>"$work/view.err" &
view=$!
pids+=($view)
wait_for_line "$work/view.err" "Foxglove: ws://" 20 "the view's Foxglove server" "$view"
"$BIN/octo-delta" synth --pace 0.5 -o "$work/live.graph" 2>"$work/synth.err" &
pids+=($!)
"$BIN/octo-delta" map "$work/live.graph" --follow --port "$side_a" --exit-when-done \
  2>"$work/map.err" &
mapper=$!
pids+=($mapper)

topics=/octo_delta/view,/octo_delta/vehicle,/octo_delta/log
check map-live --layout layout-map.json --ws "ws://127.0.0.1:$port/?token=$token" \
  --expect "$topics" --expect-drawn 10 --settle-s 45
# The mapper ends once the view has acknowledged everything (the survey takes 40 s).
deadline=$(($(date +%s) + 120))
while kill -0 "$mapper" 2>/dev/null; do
  [ "$(date +%s)" -lt "$deadline" ] || fail_setup "the mapper still runs 120 s after the checks: $(tail -3 "$work/map.err")"
  sleep 0.5
done
rc=0
wait "$mapper" || rc=$?
if [ "$rc" = 0 ]; then
  echo "mapper: $(grep -c "mapped scan" "$work/map.err") scans mapped, all acknowledged"
else
  echo "mapper: exited $rc: $(tail -3 "$work/map.err")"
  status=1
fi
last=$(grep -o "scan [0-9]*: [a-z]* of [0-9]* bytes applied" "$work/view.err" | tail -1 || true)
if [ "${last%%:*}" = "scan 79" ]; then
  echo "view: $last (the survey's last scan)"
else
  echo "view: the last scan applied is not the survey's last (79): ${last:-none}"
  status=1
fi
check map-view --layout layout-map.json --ws "ws://127.0.0.1:$port" --view-only \
  --expect-drawn 10 --settle-s 5
stop "$view" "$work/view.err" "the view"
if [ -s "$work/view.ot" ] && [ -s "$work/data/view.mcap" ]; then
  echo "view: stopped by SIGINT, wrote view.ot ($(stat -c %s "$work/view.ot") bytes) and" \
    "view.mcap ($(stat -c %s "$work/data/view.mcap") bytes)"
else
  echo "view: stopped by SIGINT, left no view.ot or no view.mcap"
  status=1
fi
warned_of_studio view "$work/view.err" "$token" \
  "(/move_base_simple/goal): refused" "(/clicked_point): refused" "(/initialpose): refused" \
  "publishing refused: its URL has no control token"

check map-file --layout layout-map.json --remote-file "${studio}data/view.mcap" \
  --expect "$topics" --expect-drawn 0.1
check map-local-file --layout layout-map.json --local-file "$work/data/view.mcap" \
  --expect "$topics" --expect-drawn 0.1
finish "octo-delta's live map, live and from its log"
