#!/usr/bin/env bash
# The ROS 2 layer measured against a real DDS (issue 47): Eclipse Cyclone DDS from PyPI (the
# peer, tests/ros2/cyclone_peer.py) and crates/ros2/examples/ros2_echo.rs (the layer, release
# build) on loopback, one domain:
#   discovery  from the echo's start to both of the peer's endpoints matched (median of 3)
#   latency    half the median round trip (peer -> echo -> peer) of a pose, a 1 MB and a 5 MB
#              PointCloud2 (5 each), reliable, keep-last 4
#   build      the layer's cold release build (rustdds and its crates, in a fresh target
#              directory), and the echo's binary size, as built and stripped
#   tools      whether the tools without ROS 2 link it (cargo tree)
# Usage: scripts/ros2-measure.sh [DOMAIN]   (default 97). Needs python3 with cyclonedds.
set -euo pipefail
cd "$(dirname "$0")/.."
domain=${1:-97}
peer=tests/ros2/cyclone_peer.py
tmp=$(mktemp -d)
trap 'rm -rf "$tmp"' EXIT
cargo build --release --quiet -p rovlink-ros2 --examples
echo_bin=target/release/examples/ros2_echo
now() { date +%s.%N; }

discovery=()
for k in 1 2 3; do
    python3 "$peer" --domain "$domain" --timeout 60 probe --type pose --count 1 \
        > "$tmp/d$k.json" 2> "$tmp/d$k.err" &
    pid=$!
    until grep -q "waiting for the echo" "$tmp/d$k.err" 2>/dev/null; do sleep 0.05; done
    t=$(now)
    "$echo_bin" "$domain" geometry_msgs/msg/PoseStamped /probe/in /probe/out 30 > /dev/null &
    echo_pid=$!
    wait $pid
    kill $echo_pid 2>/dev/null || true
    wait $echo_pid 2>/dev/null || true
    discovery+=("$(python3 -c "import json,sys; print(json.load(open('$tmp/d$k.json'))['matched_unix_s'] - $t)")")
done

run_probe() { # TYPE SIZES
    "$echo_bin" "$domain" "$1" /probe/in /probe/out 120 > /dev/null &
    local echo_pid=$!
    python3 "$peer" --domain "$domain" --timeout 60 probe --type "$2" --sizes "$3" --count 5
    kill $echo_pid 2>/dev/null || true
    wait $echo_pid 2>/dev/null || true
}
poses=$(run_probe geometry_msgs/msg/PoseStamped pose 0)
clouds=$(run_probe sensor_msgs/msg/PointCloud2 cloud 1000000,5000000)

cold=$tmp/target
t0=$(now)
CARGO_TARGET_DIR=$cold cargo build --release --quiet -p rovlink-ros2 --examples
t1=$(now)
size=$(stat -c %s "$echo_bin")
strip -o "$tmp/echo.stripped" "$echo_bin"
stripped=$(stat -c %s "$tmp/echo.stripped")

python3 - "$poses" "$clouds" "${discovery[@]}" <<PY
import json, statistics, sys
poses, clouds = json.loads(sys.argv[1]), json.loads(sys.argv[2])
disc = sorted(float(x) for x in sys.argv[3:])
print("discovery (echo start -> matched): median %.3f s (of %s)" % (statistics.median(disc), ", ".join("%.3f" % d for d in disc)))
p = poses["results"]["0"]
print("pose:  one-way %.2f ms (half the median round trip; max round trip %.2f ms)" % (p["rtt_median_s"] * 500, p["rtt_max_s"] * 1000))
for size, r in clouds["results"].items():
    print("cloud %d MB: one-way %.1f ms (half the median round trip; max round trip %.1f ms)" % (int(size) // 1000000, r["rtt_median_s"] * 500, r["rtt_max_s"] * 1000))
print("layer cold release build (rustdds and its crates, fresh target dir): %.0f s; echo binary: %.2f MB as built (line tables), %.2f MB stripped" % ($t1 - $t0, $size / 1e6, $stripped / 1e6))
PY
for tool in debt-encode debt-decode rcp-pack rcp-dump link-sim modem-bench octo-delta tdma-run; do
    if cargo tree --offline -e normal -p "$tool" --prefix none --format '{p}' | grep -q '^rustdds '; then
        echo "$tool: links the DDS"
    else
        echo "$tool: does not link the DDS"
    fi
done
