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
# Usage: scripts/tdma-speed.sh [--against BIN] [RUNS]   (default 7)
set -euo pipefail
cd "$(dirname "$0")/.."
against=
if [ "${1:-}" = --against ]; then
    against=$(realpath "$2")
    shift 2
fi
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
    python3 - "${b1[*]}" "${a1[*]}" "${b3[*]}" "${a3[*]}" <<'PY'
import statistics, sys
b1, a1, b3, a3 = ([float(v) for v in arg.split()] for arg in sys.argv[1:])
print("| session (whole process, medians) | before s | after s | after / before |")
print("|---|---|---|---|")
for name, b, a in (("1 h single session", b1, a1), ("3-node relay hour", b3, a3)):
    mb, ma = statistics.median(b), statistics.median(a)
    print(f"| {name} | {mb:.3f} | {ma:.3f} | {ma / mb:.2f} |")
PY
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
