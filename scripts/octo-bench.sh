#!/usr/bin/env bash
# octo-delta build against OctoMap's graph2tree on the same .graph, in the same run: whole-process
# wall time and peak memory (median of RUNS), at 0.1 and 0.15 m, and whether the maps are the same
# (.ot and .bt byte for byte, compare_octrees' KLD). graph2tree also prints its own insertion
# time; ours is printed by octo-delta (both medians are shown).
#
# Usage: scripts/octo-bench.sh [GRAPH] [RUNS]
#   GRAPH: a scan graph (default: octo-delta's synthetic survey, 80 scans, ~1M points)
#   RUNS:  repetitions per tool and resolution (default 5)
# Needs graph2tree and compare_octrees (Debian: apt-get install octomap-tools) and python3.
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
for tool in graph2tree compare_octrees; do
    command -v $tool >/dev/null || { echo "octo-bench: $tool missing: apt-get install octomap-tools" >&2; exit 2; }
done
measure() { # label, then the command; appends "label wall_s peak_kb insert_s" to $work/rows
    local label=$1; shift
    /usr/bin/time -f "%e %M" -o "$work/time" "$@" >"$work/out" 2>"$work/err" || { cat "$work/err" >&2; exit 1; }
    local insert
    insert=$(grep -ho "time to insert scans: [0-9.e-]*" "$work/out" "$work/err" | awk '{print $5}' || true)
    [ -n "$insert" ] || insert=$(grep -ho "([0-9.]* s inserting)" "$work/err" | tr -d '(' | awk '{print $1}' || true)
    echo "$label $(cat "$work/time") ${insert:-nan}" >> "$work/rows"
}
: > "$work/rows"
for res in 0.1 0.15; do
    for k in $(seq 1 "$runs"); do
        # Alternate the tools so drifts in the machine's load hit both alike.
        measure "graph2tree@$res" graph2tree -i "$graph" -o "$work/ref$res.bt" -res "$res"
        measure "ours-1thread@$res" "$bin" build "$graph" --res "$res" --no-color --threads 1 -o "$work/d.odl" --ot "$work/ours$res.ot" --bt "$work/ours$res.bt"
        measure "ours@$res" "$bin" build "$graph" --res "$res" --no-color -o "$work/d.odl"
    done
    same_ot=$(cmp -s "$work/ours$res.ot" "$work/ref$res.bt.ot" && echo yes || echo NO)
    same_bt=$(cmp -s "$work/ours$res.bt" "$work/ref$res.bt" && echo yes || echo NO)
    kld=$(compare_octrees "$work/ours$res.ot" "$work/ref$res.bt.ot" 2>&1 | grep -o "KLD: .*" | tail -1)
    echo "same@$res $same_ot $same_bt ${kld#KLD: }" >> "$work/rows"
done
points=$("$bin" build "$graph" --res 0.1 --no-color -o "$work/d.odl" 2>&1 | grep -o "[0-9]* scans, [0-9]* points")
python3 - "$work/rows" "$points" "$(nproc)" <<'PY'
import statistics, sys
rows = [l.split() for l in open(sys.argv[1])]
print(f"input: {sys.argv[2]}; machine: {sys.argv[3]} cores; medians of the runs")
print()
print("| res | tool | wall s | peak MB | insert s | wall vs graph2tree | peak vs graph2tree |")
print("|---|---|---|---|---|---|---|")
same = {}
for res in ("0.1", "0.15"):
    m = {}
    for tool in ("graph2tree", "ours-1thread", "ours"):
        r = [x for x in rows if x[0] == f"{tool}@{res}"]
        wall = statistics.median(float(x[1]) for x in r)
        peak = statistics.median(float(x[2]) for x in r) / 1024
        ins = statistics.median(float(x[3]) for x in r)
        m[tool] = (wall, peak, ins)
    for tool, (wall, peak, ins) in m.items():
        g = m["graph2tree"]
        name = {"graph2tree": "graph2tree", "ours-1thread": "octo-delta --threads 1", "ours": "octo-delta (all cores)"}[tool]
        print(f"| {res} | {name} | {wall:.3f} | {peak:.1f} | {ins:.3f} | {g[0] / wall:.2f}x faster | {peak / g[1]:.2f} |")
    s = [x for x in rows if x[0] == f"same@{res}"][0]
    same[res] = s[1:]
print()
for res, (ot, bt, *kld) in same.items():
    print(f"res {res}: .ot identical: {ot}, .bt identical: {bt}, compare_octrees KLD: {' '.join(kld)}")
PY
