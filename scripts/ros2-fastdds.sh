#!/usr/bin/env bash
# The ROS 2 exchanges of tests/ros2_live.rs run against eProsima Fast DDS, ROS 2's default RMW's
# DDS (issue 47; a script, not CI): Debian 12's libfastrtps-dev 2.9 and fastddsgen, types
# generated from tests/ros2/fastdds/ros2_msgs.idl, the peer tests/ros2/fastdds/fastdds_peer.cpp.
#
#   fastdds-to-build    Fast DDS publishes a survey bag's clouds, /tf and /tf_static live (the
#                       bag's CDR through the generated types; clouds and /tf reliable, volatile,
#                       keep-all; /tf_static reliable, transient-local), two clouds a second,
#                       into `octo-delta build ros2:/points`, ended by SIGTERM once its --stats
#                       has every scan: pass when its .ot is the bag's offline .ot, byte for byte.
#   view-to-fastdds     `octo-delta map` streams a survey over `link-sim --pty` (satellite models)
#                       to `octo-delta view --ros2`; a late Fast DDS subscriber (reliable,
#                       transient-local, keep-last 1) takes the Octomap on
#                       /octo_delta/octomap_full whose data has the final map's length: pass when
#                       its data is the offline map's .ot body, byte for byte (and the view's own
#                       .ot is that map).
#
# Prints `PASS <name>` or `FAIL <name>: <reason>` per exchange; exits 0 only if all pass. On a
# failure the working directory (logs, maps) is kept and named on stderr.
# The peer's variants (tests/ros2/fastdds/fastdds_peer.cpp) pass through the environment:
# FASTDDS_PEER_TRANSPORT=builtin (shared memory + UDPv4, multicast discovery, as rmw_fastrtps),
# FASTDDS_PEER_PUBLISH=sync (synchronous publication).
# Usage: scripts/ros2-fastdds.sh [DOMAIN]   (default 100 + PID % 100). Installs what it needs
# with apt-get when missing (Debian 12); builds octo-delta and link-sim (debug) when missing.
set -uo pipefail
cd "$(dirname "$0")/.."
root=$PWD
domain=${1:-$((100 + $$ % 100))}
octo=$root/target/debug/octo-delta
linksim=$root/target/debug/link-sim
src=$root/tests/ros2/fastdds
scans=6

note() { echo "ros2-fastdds: $*" >&2; }

missing=()
for p in libfastrtps-dev fastddsgen g++ cmake; do
    dpkg -s "$p" > /dev/null 2>&1 || missing+=("$p")
done
if [ ${#missing[@]} -gt 0 ]; then
    note "installing ${missing[*]}"
    DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends "${missing[@]}" >&2 ||
        { echo "FAIL setup: apt-get install ${missing[*]} failed"; exit 1; }
fi
if [ ! -x "$octo" ] || [ ! -x "$linksim" ]; then
    note "building octo-delta and link-sim (debug)"
    cargo build -q -p octo-delta -p link-sim >&2 || { echo "FAIL setup: cargo build failed"; exit 1; }
fi

tmp=$(mktemp -d /tmp/ros2-fastdds.XXXXXX)
pids=()
failed=0
cleanup() {
    for p in "${pids[@]}"; do kill "$p" 2> /dev/null; done
    for p in "${pids[@]}"; do wait "$p" 2> /dev/null; done
    if [ "$failed" = 0 ]; then rm -rf "$tmp"; else note "kept $tmp"; fi
}
trap cleanup EXIT

# wait_until SECONDS COMMAND...: until COMMAND succeeds (every 0.1 s), at most SECONDS.
wait_until() {
    local deadline=$((SECONDS + $1))
    shift
    until "$@"; do
        [ $SECONDS -ge $deadline ] && return 1
        sleep 0.1
    done
}
said() { grep -qF -- "$2" "$1" 2> /dev/null; }
rows_at_least() { [ "$(wc -l 2> /dev/null < "$1" || echo 0)" -ge "$2" ]; }
gone() { ! kill -0 "$1" 2> /dev/null; }
# finish PID SECONDS: waits for PID to end (at most SECONDS, then kills it); its exit status.
finish() {
    wait_until "$2" gone "$1" || kill -KILL "$1" 2> /dev/null
    wait "$1" 2> /dev/null
}
why_of() { python3 -c 'import json,sys
try: print(json.loads(open(sys.argv[1]).read().strip().splitlines()[-1]).get("why","no reason given"))
except Exception as e: print("no JSON line (%s)" % e)' "$1"; }
body_len() { python3 -c 'import sys; d=open(sys.argv[1],"rb").read(); print(len(d)-d.index(b"data\n")-5)' "$1"; }
pass() { echo "PASS $1"; }
fail() { echo "FAIL $1: $2"; failed=1; }

# --- the peer: types from the IDL by fastddsgen, one C++ program --------------------------------
gen=$tmp/gen
mkdir -p "$gen"
if ! fastddsgen -replace -d "$gen" "$src/ros2_msgs.idl" > "$tmp/fastddsgen.log" 2>&1; then
    fail setup "fastddsgen failed: $(tail -3 "$tmp/fastddsgen.log" | tr '\n' ' ')"
    exit 1
fi
peer=$tmp/fastdds_peer
if ! g++ -O1 -std=c++17 -I"$gen" "$src/fastdds_peer.cpp" "$gen/ros2_msgs.cxx" \
    "$gen/ros2_msgsPubSubTypes.cxx" -o "$peer" -lfastrtps -lfastcdr > "$tmp/g++.log" 2>&1; then
    fail setup "the peer does not build: $(grep -m3 error "$tmp/g++.log" | tr '\n' ' ')"
    exit 1
fi
note "domain $domain; Fast DDS $(dpkg-query -W -f '${Version}' libfastrtps-dev), fastddsgen $(dpkg-query -W -f '${Version}' fastddsgen); in $tmp"

# --- the survey ----------------------------------------------------------------------------------
cd "$tmp"
"$octo" synth --scans $scans -o s.graph > /dev/null &&
    python3 "$root/tests/bags/survey_bag.py" --graph s.graph --kind mcap-none --pose tf --color \
        --out bag.mcap > /dev/null &&
    python3 "$src/dump_bag.py" bag.mcap msgs > msgs.json &&
    "$octo" build bag.mcap -q -o off.odl --ot want.ot &&
    "$octo" build s.graph -q -o goff.odl && "$octo" apply goff.odl -o gwant.ot > /dev/null ||
    { fail setup "the survey, its bag or the offline maps could not be made"; exit 1; }

# --- a: Fast DDS publishes, octo-delta build reads -----------------------------------------------
exchange_a() {
    local name=fastdds-to-build
    "$octo" build ros2:/points --ros2-domain "$domain" --threads 1 -o live.odl --ot live.ot \
        --stats live.csv > build.out 2> build.err &
    local build=$!
    pids+=("$build")
    # The peer waits for the build's readers to match (60 s), then plays 6 clouds at 2 a second.
    timeout 120 "$peer" play "$domain" msgs/index.tsv 0.5 60 > play.json 2> play.err
    local rc=$?
    if [ $rc -ne 0 ]; then
        fail $name "the Fast DDS publisher failed (exit $rc): $(why_of play.json)"
        return
    fi
    if ! wait_until 60 rows_at_least live.csv $((scans + 1)); then
        fail $name "the build's --stats has $(wc -l 2> /dev/null < live.csv || echo 0) lines, not $((scans + 1)), 60 s after the publisher ended ($(tail -1 build.err))"
        return
    fi
    kill -TERM "$build"
    finish "$build" 30
    rc=$?
    if [ $rc -ne 143 ]; then
        fail $name "the build ended with $rc on SIGTERM, not 143: $(tail -1 build.err)"
    elif ! cmp -s live.ot want.ot; then
        fail $name "live.ot ($(stat -c %s live.ot 2> /dev/null) B) differs from the bag's offline want.ot ($(stat -c %s want.ot) B): $(cmp live.ot want.ot 2>&1 | head -1)"
    else
        pass $name
    fi
}

# --- b: octo-delta view publishes, a late Fast DDS subscriber takes the map ----------------------
exchange_b() {
    local name=view-to-fastdds
    "$linksim" --pty --model satellite-up --reverse-model satellite-down > link.out 2> link.err &
    pids+=($!)
    if ! wait_until 20 rows_at_least link.out 2; then
        fail $name "link-sim gave no two pty paths in 20 s"
        return
    fi
    local a b
    a=$(sed -n 1p link.out)
    b=$(sed -n 2p link.out)
    "$octo" view --port "$b" -o view.ot --ros2 --ros2-domain "$domain" \
        --ros2-full-topic /octo_delta/octomap_full --ros2-period 0.2 > view.out 2> view.err &
    local view=$!
    pids+=("$view")
    if ! wait_until 30 said view.err "ROS 2: the view on /octo_delta/octomap"; then
        fail $name "the view did not say it publishes in 30 s: $(tail -1 view.err)"
        return
    fi
    if ! timeout 300 "$octo" map s.graph --port "$a" --exit-when-done > map.out 2> map.err; then
        fail $name "the mapper failed: $(tail -1 map.err)"
        return
    fi
    if ! wait_until 120 said view.err "scan $((scans - 1)): "; then
        fail $name "the view did not apply scan $((scans - 1)) in 120 s: $(tail -1 view.err)"
        return
    fi
    # The run is over; the late subscriber joins and waits for the final map by its length.
    local want
    want=$(body_len gwant.ot)
    timeout 120 "$peer" latched "$domain" /octo_delta/octomap_full got.data "$want" 60 \
        > latched.json 2> latched.err
    local rc=$?
    kill -TERM "$view"
    finish "$view" 30
    local vrc=$?
    if [ $rc -ne 0 ]; then
        fail $name "the Fast DDS subscriber failed (exit $rc): $(why_of latched.json)"
    elif ! python3 -c 'import sys
d=open(sys.argv[1],"rb").read()
sys.exit(open(sys.argv[2],"rb").read() != d[d.index(b"data\n")+5:])' gwant.ot got.data; then
        fail $name "the Octomap's data ($(stat -c %s got.data) B) differs from the offline map's .ot body ($want B)"
    elif [ $vrc -ne 143 ]; then
        fail $name "the view ended with $vrc on SIGTERM, not 143: $(tail -1 view.err)"
    elif ! cmp -s view.ot gwant.ot; then
        fail $name "the view's own view.ot differs from the offline map (the data Fast DDS got is the offline map's)"
    else
        pass $name
    fi
}

exchange_a
exchange_b
exit $failed
