#!/usr/bin/env bash
# Speed of a simulated session (issue 6's bar: one hour, about 5,600 slots with every image
# DEBT-encoded, in at most 1 s). Runs a 3600 s S100 session RUNS times and, as the anchor in
# the same run, the link alone carrying the same number of frames (modem-bench --sim, 57-byte
# frames back to back); prints medians and the ratio.
#
# With --against BIN (a previous tdma-run, e.g. a release binary kept aside), it times instead
# the 1-hour default session and the 3-node relay scenario's hour of BIN and of ours, in
# interleaved pairs, and prints the medians and ratios (issue 30's "no slower than before").
#
# With --against BIN --week (issue 32), it also times the default session over a week
# (--duration 604800) of ours and, since the week of an older binary may take minutes, one
# day (--duration 86400) of BIN, scaled by 7 and labelled so; WEEK_RUNS runs of each (default
# 1, interleaved, medians). It also measures the peak RSS (/usr/bin/time -f %M, KB) of ours for
# one hour, one day and one week of the same session, which should be about equal (memory
# flat in duration).
#
# Interface (for scripts/speed.sh and other callers):
#   scripts/tdma-speed.sh [--against BIN [--week [--week-runs N]]] [RUNS]   (RUNS default 7)
#   - builds ours (cargo build --release) first; the seeds are 1..RUNS (1..N for the week);
#   - prints Markdown tables on standard output, nothing else: with --against, one row per
#     session "| name | before s | after s | after / before |" (1 h single session, 3-node
#     relay hour, and with --week "1 week single session (before: 7 x 1 day)"), then with
#     --week "| peak RSS KB | 1 h | 1 day | 1 week |" and one row for ours;
#   - exits 0 when every run succeeded, non-zero (set -e) when one failed.
set -euo pipefail
cd "$(dirname "$0")/.."
against= week= week_runs=1
while [ $# -gt 0 ]; do
    case "$1" in
    --against) against=$(realpath "$2"); shift 2 ;;
    --week) week=1; shift ;;
    --week-runs) week_runs=$2; shift 2 ;;
    *) break ;;
    esac
done
runs=${1:-7}
cargo build --release --quiet --bin tdma-run --bin modem-bench
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
seconds() { python3 -c "import time,subprocess,sys; t=time.perf_counter(); subprocess.run(sys.argv[1:], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL); print(time.perf_counter()-t)" "$@"; }
if [ -n "$against" ]; then
    single=(--sim --duration 3600 --metrics "$work/m.json")
    network=(--scenario scenarios/relay-rf.json --duration 3600 --metrics "$work/m.json")
    b1=() a1=() b3=() a3=()
    for k in $(seq 1 "$runs"); do
        b1+=("$(seconds "$against" "${single[@]}" --seed "$k")")
        a1+=("$(seconds target/release/tdma-run "${single[@]}" --seed "$k")")
        b3+=("$(seconds "$against" "${network[@]}" --seed "$k")")
        a3+=("$(seconds target/release/tdma-run "${network[@]}" --seed "$k")")
    done
    bw=() aw=()
    if [ -n "$week" ]; then
        for k in $(seq 1 "$week_runs"); do
            day=$(seconds "$against" --sim --duration 86400 --metrics "$work/m.json" --seed "$k")
            bw+=("$(python3 -c "import sys; print(7 * float(sys.argv[1]))" "$day")")
            aw+=("$(seconds target/release/tdma-run --sim --duration 604800 --metrics "$work/m.json" --seed "$k")")
        done
    fi
    python3 - "${b1[*]}" "${a1[*]}" "${b3[*]}" "${a3[*]}" "${bw[*]}" "${aw[*]}" <<'PY'
import statistics, sys
b1, a1, b3, a3, bw, aw = ([float(v) for v in arg.split()] for arg in sys.argv[1:])
print("| session (whole process, medians) | before s | after s | after / before |")
print("|---|---|---|---|")
rows = [("1 h single session", b1, a1), ("3-node relay hour", b3, a3)]
if aw:
    rows.append(("1 week single session (before: 7 x 1 day)", bw, aw))
for name, b, a in rows:
    mb, ma = statistics.median(b), statistics.median(a)
    print(f"| {name} | {mb:.3f} | {ma:.3f} | {ma / mb:.2f} |")
PY
    if [ -n "$week" ]; then
        rss=()
        for duration in 3600 86400 604800; do
            /usr/bin/time -f %M -o "$work/rss" target/release/tdma-run --sim --duration "$duration" \
                --metrics "$work/m.json" --seed 1 >/dev/null 2>&1
            rss+=("$(tail -n 1 "$work/rss")")
        done
        echo
        echo "| peak RSS KB | 1 h | 1 day | 1 week |"
        echo "|---|---|---|---|"
        echo "| ours, --sim --seed 1 | ${rss[0]} | ${rss[1]} | ${rss[2]} |"
    fi
    exit 0
fi
session=() anchor=()
for k in $(seq 1 "$runs"); do
    session+=("$(seconds target/release/tdma-run --sim --ipg 640 --duration 3600 --seed "$k" --metrics "$work/m.json")")
    anchor+=("$(seconds target/release/modem-bench --sim s100 --count 11250 --size 57 --seed "$k" -q -o "$work/p.csv")")
done
python3 - "$work/m.json" "${session[*]}" "${anchor[*]}" <<'PY'
import json, statistics, sys
m = json.load(open(sys.argv[1]))
s = [float(v) for v in sys.argv[2].split()]
a = [float(v) for v in sys.argv[3].split()]
slots = m["operator_to_rov"]["frames_sent"]
print(f"1-hour session: {slots} slots, {m['images_started']} images encoded, {m['images_completed']} completed")
print(f"| what | median s | min s | max s |")
print(f"|---|---|---|---|")
print(f"| tdma-run --sim --duration 3600 (whole process) | {statistics.median(s):.3f} | {min(s):.3f} | {max(s):.3f} |")
print(f"| anchor: modem-bench --sim, 11,250 frames | {statistics.median(a):.3f} | {min(a):.3f} | {max(a):.3f} |")
print(f"ratio session / anchor: {statistics.median(s) / statistics.median(a):.2f}; bar: session <= 1 s")
PY
