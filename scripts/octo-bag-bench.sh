#!/usr/bin/env bash
# octo-delta build from robot logs against the same scans from a .graph, in the same run:
# whole-process wall time and peak memory (median of RUNS) for a zstd MCAP bag, an lz4 one, an
# uncompressed one and a rosbag2 sqlite3 directory, all written by the real writers
# (tests/bags/survey_bag.py: Python `mcap` and `rosbags`) with poses on /tf, and whether each map
# is the .graph's (the .bt byte for byte against graph2tree's, and compare_octrees' KLD between
# the .ot files).
#
# Bars: a zstd bag costs at most 1.1x the .graph build (issue 48; issue 15's was 1.3x): the bag
# is read, decompressed and decoded on its own thread while the map works; its peak memory is at
# most the .graph build's (map + the scans read ahead) plus one decompressed chunk plus one cloud
# message.
#
# Usage: scripts/octo-bag-bench.sh [GRAPH] [RUNS]
#   GRAPH: a scan graph (default: octo-delta's synthetic survey, 80 scans, ~1M points)
#   RUNS:  repetitions per input (default 5)
# Needs graph2tree, compare_octrees (apt-get install octomap-tools) and python3 with mcap,
# mcap-ros2-support and rosbags (pip install mcap mcap-ros2-support rosbags).
set -euo pipefail
cd "$(dirname "$0")/.."
runs=${2:-5}
cargo build --release --quiet --bin octo-delta
bin=target/release/octo-delta
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
graph=${1:-}
if [ -z "$graph" ]; then
    graph=$work/survey.graph
    "$bin" synth -o "$graph"
fi
for tool in graph2tree compare_octrees python3; do
    command -v $tool >/dev/null || { echo "octo-bag-bench: $tool missing" >&2; exit 2; }
done
declare -A input=([graph]=$graph)
for kind in mcap-zstd mcap-lz4 mcap-none db3; do
    out=$work/bag-$kind; [[ $kind == mcap-* ]] && out=$out.mcap
    python3 tests/bags/survey_bag.py --graph "$graph" --kind "$kind" --pose tf --out "$out" >/dev/null
    input[$kind]=$out
done
res=0.1
graph2tree -i "$graph" -o "$work/ref.bt" -res $res >/dev/null 2>&1
: > "$work/rows"
for k in $(seq 1 "$runs"); do
    # Alternate the inputs so drifts in the machine's load hit all alike.
    for kind in graph mcap-zstd mcap-lz4 mcap-none db3; do
        /usr/bin/time -f "%e %M" -o "$work/time" "$bin" build "${input[$kind]}" --res $res --no-color \
            -q -o "$work/d.odl" --bt "$work/$kind.bt" --ot "$work/$kind.ot" 2>"$work/err" || { cat "$work/err" >&2; exit 1; }
        echo "$kind $(cat "$work/time")" >> "$work/rows"
    done
done
for kind in graph mcap-zstd mcap-lz4 mcap-none db3; do
    same=$(cmp -s "$work/$kind.bt" "$work/ref.bt" && echo yes || echo NO)
    kld=$(compare_octrees "$work/$kind.ot" "$work/ref.bt.ot" 2>&1 | grep -o "KLD: .*" | tail -1 || true)
    echo "same $kind $same ${kld#KLD: }" >> "$work/rows"
done
python3 - "$work/rows" "${input[mcap-zstd]}" "$(nproc)" "$(du -b "${input[mcap-zstd]}" | cut -f1)" <<'PY'
import statistics, sys
from mcap.reader import make_reader
rows = [l.split() for l in open(sys.argv[1])]
summary = make_reader(open(sys.argv[2], "rb")).get_summary()
chunk = max(c.uncompressed_size for c in summary.chunk_indexes)
biggest = 0
for _, _, msg in make_reader(open(sys.argv[2], "rb")).iter_messages(topics=["/points"]):
    biggest = max(biggest, len(msg.data))
print(f"machine: {sys.argv[3]} cores; medians of the runs; zstd bag {int(sys.argv[4]) / 1e6:.1f} MB, "
      f"largest chunk {chunk / 1e6:.2f} MB uncompressed, largest cloud message {biggest / 1e6:.2f} MB")
print()
print("| input | wall s | peak MB | wall vs .graph | peak - .graph's MB | budget MB (chunk + message) | same .bt | KLD vs graph2tree |")
print("|---|---|---|---|---|---|---|---|")
m = {}
for kind in ("graph", "mcap-zstd", "mcap-lz4", "mcap-none", "db3"):
    r = [x for x in rows if x[0] == kind]
    m[kind] = (statistics.median(float(x[1]) for x in r), statistics.median(float(x[2]) for x in r) / 1024)
same = {x[1]: x[2:] for x in rows if x[0] == "same"}
g = m["graph"]
for kind, (wall, peak) in m.items():
    budget = "" if kind == "graph" else f"{(chunk + biggest) / 1e6:.2f}" if kind.startswith("mcap") else f"{biggest / 1e6:.2f}"
    print(f"| {kind} | {wall:.3f} | {peak:.1f} | {wall / g[0]:.2f}x | {peak - g[1]:+.1f} | {budget} | {same[kind][0]} | {' '.join(same[kind][1:])} |")
PY
