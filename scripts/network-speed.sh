#!/usr/bin/env bash
# Speed of a simulated multi-vehicle network (issue 17's bar: one hour of the three-node relay
# scenario in at most 2 s). Runs scenarios/relay-rf.json for 3600 s RUNS times and, as the
# anchor in the same run, the single-vehicle session of the same hour (tdma-run --sim); prints
# medians and the ratio.
#
# Usage: scripts/network-speed.sh [RUNS]   (default 5)
set -euo pipefail
cd "$(dirname "$0")/.."
runs=${1:-5}
cargo build --release --quiet --bin tdma-run
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
seconds() { python3 -c "import time,subprocess,sys; t=time.perf_counter(); subprocess.run(sys.argv[1:], check=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL); print(time.perf_counter()-t)" "$@"; }
network=() anchor=()
for k in $(seq 1 "$runs"); do
    network+=("$(seconds target/release/tdma-run --scenario scenarios/relay-rf.json --duration 3600 --seed "$k" --metrics "$work/n.json")")
    anchor+=("$(seconds target/release/tdma-run --sim --ipg 640 --duration 3600 --seed "$k" --metrics "$work/m.json")")
done
python3 - "$work/n.json" "${network[*]}" "${anchor[*]}" <<'PY'
import json, statistics, sys
m = json.load(open(sys.argv[1]))
n = [float(v) for v in sys.argv[2].split()]
a = [float(v) for v in sys.argv[3].split()]
v = m["vehicles"]
print(f"1-hour network: cycle {m['cycle_s']*1e3:.1f} ms; images completed "
      + ", ".join(f"vehicle {k}: {x['images_completed']}" for k, x in v.items())
      + f"; relay forwarded {m['nodes']['1']['frames_forwarded']} frames")
print("| what | median s | min s | max s |")
print("|---|---|---|---|")
print(f"| tdma-run --scenario relay-rf.json --duration 3600 (whole process) | {statistics.median(n):.3f} | {min(n):.3f} | {max(n):.3f} |")
print(f"| anchor: tdma-run --sim --duration 3600 (one vehicle) | {statistics.median(a):.3f} | {min(a):.3f} | {max(a):.3f} |")
print(f"ratio network / anchor: {statistics.median(n) / statistics.median(a):.2f}; bar: network <= 2 s")
PY
