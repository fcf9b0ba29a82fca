#!/usr/bin/env bash
# Hostile peers on the ROS 2 domain (issue 47), against Cyclone DDS from PyPI:
#   flood     a simulated session paced to real time (--pace 1, seed 7) with --ros2
#             --ros2-control while a peer advertises 1,000 topics and floods /rov/cmd_vel (every
#             other Twist NaN) for the whole run: the frames both ways and the images must equal
#             a quiet run's, the memory (max RSS) stay within 64 MiB of it, and the NaN be
#             refused with one line
#   cloud     a 100 MB PointCloud2 (6.25 million points) on /points to `octo-delta build
#             ros2:/points`, in a frame no transform names: taken, then skipped after the TF
#             wait with one line; the build's peak memory stays under 1 GiB
# Usage: scripts/ros2-hostile.sh [DOMAIN] (default 93); debug tools in target/debug.
set -euo pipefail
cd "$(dirname "$0")/.."
domain=${1:-93}
peer=tests/ros2/cyclone_peer.py
bin=target/debug
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
fail=0

session() { # NAME [peer flood args...]
    local name=$1; shift
    local flood_pid=
    if [ $# -gt 0 ]; then
        python3 "$peer" --domain "$domain" flood "$@" > "$tmp/$name.flood" &
        flood_pid=$!
    fi
    /usr/bin/time -f '%M' -o "$tmp/$name.rss" "$bin/tdma-run" --duration 20 --pace 1 --seed 7 \
        --ros2 --ros2-domain "$domain" --ros2-control --metrics "$tmp/$name.json" \
        2> "$tmp/$name.err" > /dev/null
    [ -n "$flood_pid" ] && wait "$flood_pid"
    true
}
session quiet
session flood --seconds 22 --topics 1000 --nan
python3 - "$tmp" <<'PY' || fail=1
import json, sys
d = sys.argv[1]
q, f = (json.load(open(f"{d}/{n}.json")) for n in ("quiet", "flood"))
rss = {n: int(open(f"{d}/{n}.rss").read().split()[-1]) for n in ("quiet", "flood")}
err = open(f"{d}/flood.err").read()
sent = json.load(open(f"{d}/flood.flood"))
TIMING = ("rov_to_operator", "operator_to_rov", "images_started", "images_completed", "image_period_s")
same = all(q.get(k) == f.get(k) for k in TIMING)
nan_lines = err.count("cmd_vel refused")
print(f"flood: {sent['twists']} Twists (half NaN) and {sent['topics']} topics; timing figures equal: {same}; "
      f"max RSS quiet {rss['quiet']} KiB, flooded {rss['flood']} KiB; NaN refusal lines: {nan_lines}")
ok = same and rss["flood"] - rss["quiet"] < 64 * 1024 and nan_lines == 1
print("PASS flood" if ok else "FAIL flood")
sys.exit(0 if ok else 1)
PY

"$bin/octo-delta" build ros2:/points --ros2-domain "$domain" -o "$tmp/c.odl" 2> "$tmp/cloud.err" &
build=$!
sleep 1
python3 "$peer" --domain "$domain" flood --seconds 0 --cloud-mb 100 > "$tmp/cloud.flood"
# Acknowledged by the build's reader; the skip is said in its summary at its end: give the
# cloud its TF wait (1 s), then stop it.
sleep 3
rss=$(awk '/VmHWM/ {print $2}' /proc/$build/status)
kill -TERM $build
wait $build || true
lines=$(grep -c "no pose" "$tmp/cloud.err" || true)
echo "cloud: a 100 MB cloud; build peak RSS ${rss} KiB; skip lines: $lines"
if [ "$lines" -ge 1 ] && [ "$rss" -lt $((1024 * 1024)) ]; then echo "PASS cloud"; else echo "FAIL cloud"; cat "$tmp/cloud.err"; fail=1; fi
exit $fail
