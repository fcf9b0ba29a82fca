#!/usr/bin/env bash
# octo-delta build against OctoMap's graph2tree on the same survey, in the same run (the tools
# interleaved, so drifts in the machine's load hit both alike): whole-process wall time and peak
# memory, medians of RUNS, with octo-delta on 1 and on 2 threads, plain and coloured; and whether
# the maps are the same (.ot and .bt byte for byte against graph2tree's, compare_octrees' KLD;
# the coloured maps of 1 and 2 threads against each other). graph2tree's own insertion time and
# octo-delta's are shown too.
#
# Two more anchors (issue 48): the same scans as a zstd MCAP bag (written by the real writer,
# tests/bags/survey_bag.py, poses on /tf) against the .graph, and the coloured build against
# OctoMap's own ColorOcTree fed the same clouds (tests/octomap/color_tree.cpp built here against
# Debian's liboctomap), its .ot compared byte for byte. Bars: bag / .graph <= 1.1x; coloured
# >= 10x ColorOcTree on 2 threads, >= 5x on 1.
#
# Usage: scripts/octo-bench.sh [--scans N] [--res R[,R...]] [--runs K] [--graph FILE] [--table]
#        scripts/octo-bench.sh [GRAPH] [RUNS]          (the older form)
#   --scans N   scans of octo-delta's synthetic survey (default 80: ~1M points; 12 288 a scan)
#   --res R     voxel edges in m, comma-separated (default 0.1,0.15)
#   --runs K    repetitions per tool, thread count and resolution (default 5)
#   --graph F   a scan graph instead of the synthetic survey (no coloured rows then)
#   --table     print only the table and the identity lines (for scripts/speed.sh)
# Example: scripts/octo-bench.sh --scans 40 --res 0.1 --runs 5 --table
# Needs graph2tree and compare_octrees (Debian: apt-get install octomap-tools), python3 with mcap
# and rosbags (the bag row), g++ and liboctomap-dev (the ColorOcTree row); a row whose needs are
# missing is left out, and said.
set -euo pipefail
cd "$(dirname "$0")/.."
runs=5 scans="" graph="" table=0 resolutions="0.1,0.15"
positional=()
while [ $# -gt 0 ]; do
    case $1 in
        --scans) scans=$2; shift 2 ;;
        --res) resolutions=$2; shift 2 ;;
        --runs) runs=$2; shift 2 ;;
        --graph) graph=$2; shift 2 ;;
        --table) table=1; shift ;;
        -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//'; exit 0 ;;
        -*) echo "octo-bench: unknown option $1 (see --help)" >&2; exit 2 ;;
        *) positional+=("$1"); shift ;;
    esac
done
[ ${#positional[@]} -ge 1 ] && graph=${positional[0]}
[ ${#positional[@]} -ge 2 ] && runs=${positional[1]}
log() { [ "$table" = 1 ] || echo "octo-bench: $*" >&2; }
for tool in graph2tree compare_octrees; do
    command -v $tool >/dev/null || { echo "octo-bench: $tool missing: apt-get install octomap-tools" >&2; exit 2; }
done
cargo build --release --quiet --bin octo-delta
bin=target/release/octo-delta
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
colored="" colortree="" bag=""
if [ -z "$graph" ]; then
    graph=$work/survey.graph
    colored=$work/survey.mcap
    "$bin" synth ${scans:+--scans "$scans"} -o "$graph"
    "$bin" synth ${scans:+--scans "$scans"} -o "$colored"
    # The coloured anchor: OctoMap's ColorOcTree fed the same clouds.
    if c++ -O2 -std=c++17 tests/octomap/color_tree.cpp -o "$work/color_tree" -loctomap -loctomath 2>"$work/cxx"; then
        cargo build --release --quiet -p rovlink-octo --example reference_scans
        target/release/examples/reference_scans "${scans:-80}" 1 "$work/scans.rvcs"
        colortree=$work/color_tree
    else
        echo "octo-bench: no ColorOcTree row: tests/octomap/color_tree.cpp does not build (apt-get install g++ liboctomap-dev)" >&2
    fi
fi
# The bag anchor: the same scans as a zstd MCAP bag, by the real writer.
if python3 tests/bags/survey_bag.py --graph "$graph" --kind mcap-zstd --pose tf --out "$work/bag.mcap" >/dev/null 2>"$work/bagerr"; then
    bag=$work/bag.mcap
else
    echo "octo-bench: no bag row: tests/bags/survey_bag.py failed (pip install mcap rosbags): $(tail -1 "$work/bagerr")" >&2
fi
measure() { # label, then the command; appends "label wall_s peak_kb insert_s" to $work/rows
    # Wall time from the clock in nanoseconds around the run (/usr/bin/time's own is in 10 ms
    # steps, too coarse for a 70 ms build); peak memory from /usr/bin/time.
    local label=$1; shift
    local t0 t1
    t0=$(date +%s%N)
    /usr/bin/time -f "%M" -o "$work/time" "$@" >"$work/out" 2>"$work/err" || { cat "$work/err" >&2; exit 1; }
    t1=$(date +%s%N)
    local insert
    insert=$(grep -ho "time to insert scans: [0-9.e-]*" "$work/out" "$work/err" | awk '{print $5}' || true)
    [ -n "$insert" ] || insert=$(grep -ho "([0-9.]* s inserting)" "$work/err" | tr -d '(' | awk '{print $1}' || true)
    echo "$label $(awk -v a="$t0" -v b="$t1" 'BEGIN{printf "%.4f", (b - a) / 1e9}') $(cat "$work/time") ${insert:-nan}" >> "$work/rows"
}
: > "$work/rows"
for res in ${resolutions//,/ }; do
    log "res $res: $runs runs"
    for k in $(seq 1 "$runs"); do
        measure "graph2tree@$res" graph2tree -i "$graph" -o "$work/ref$res.bt" -res "$res"
        for t in 1 2; do
            measure "plain$t@$res" "$bin" build "$graph" --res "$res" --no-color --threads $t -o "$work/d.odl" --ot "$work/ours$t-$res.ot" --bt "$work/ours$t-$res.bt"
            if [ -n "$bag" ]; then
                measure "bag$t@$res" "$bin" build "$bag" --res "$res" --no-color --threads $t -o "$work/b.odl" --ot "$work/bag$t-$res.ot"
            fi
            if [ -n "$colored" ]; then
                measure "colored$t@$res" "$bin" build "$colored" --res "$res" --threads $t -o "$work/c$t.odl" --ot "$work/col$t-$res.ot"
            fi
        done
        if [ -n "$colortree" ]; then
            measure "colortree@$res" "$colortree" "$work/scans.rvcs" "$res" "$work/colortree$res.ot"
        fi
    done
    same() { cmp -s "$1" "$2" && echo yes || echo NO; }
    kld=$(compare_octrees "$work/ours2-$res.ot" "$work/ref$res.bt.ot" 2>&1 | grep -o "KLD: .*" | tail -1)
    col="-" colref="-" bagsame="-"
    [ -z "$colored" ] || col=$(same "$work/col1-$res.ot" "$work/col2-$res.ot")
    [ -z "$colortree" ] || colref=$(same "$work/col2-$res.ot" "$work/colortree$res.ot")
    [ -z "$bag" ] || bagsame=$(same "$work/bag2-$res.ot" "$work/ours2-$res.ot")
    echo "same@$res $(same "$work/ours1-$res.bt" "$work/ref$res.bt") $(same "$work/ours2-$res.bt" "$work/ref$res.bt") $(same "$work/ours1-$res.ot" "$work/ref$res.bt.ot") $(same "$work/ours2-$res.ot" "$work/ref$res.bt.ot") $col $colref $bagsame ${kld#KLD: }" >> "$work/rows"
done
points=$("$bin" build "$graph" --res 0.1 --no-color -o "$work/d.odl" 2>&1 | grep -o "[0-9]* scans, [0-9]* points")
python3 - "$work/rows" "$points" "$(nproc)" "$resolutions" "$runs" <<'PY'
import statistics, sys
rows = [l.split() for l in open(sys.argv[1])]
print(f"input: {sys.argv[2]}; machine: {sys.argv[3]} cores; medians of {sys.argv[5]} runs")
print()
print("| res m | tool | wall s | peak MB | insert s | graph2tree / this (wall) |")
print("|---|---|---|---|---|---|")
names = {
    "graph2tree": "graph2tree",
    "plain1": "octo-delta --no-color --threads 1",
    "plain2": "octo-delta --no-color --threads 2",
    "colored1": "octo-delta coloured --threads 1",
    "colored2": "octo-delta coloured --threads 2",
    "bag1": "octo-delta zstd MCAP bag --no-color --threads 1",
    "bag2": "octo-delta zstd MCAP bag --no-color --threads 2",
    "colortree": "OctoMap ColorOcTree (C++, coloured)",
}
same = {}
for res in sys.argv[4].split(","):
    m = {}
    for tool in names:
        r = [x for x in rows if x[0] == f"{tool}@{res}"]
        if not r:
            continue
        wall = statistics.median(float(x[1]) for x in r)
        peak = statistics.median(float(x[2]) for x in r) / 1024
        ins = statistics.median(float(x[3]) for x in r)
        m[tool] = (wall, peak, ins)
    g = m["graph2tree"][0]
    for tool, (wall, peak, ins) in m.items():
        print(f"| {res} | {names[tool]} | {wall:.3f} | {peak:.1f} | {ins:.3f} | {g / wall:.2f}x |")
    same[res] = [x for x in rows if x[0] == f"same@{res}"][0][1:]
    for t in (1, 2):
        if f"bag{t}" in m:
            print(f"| {res} | bag / .graph, {t} thread(s) (bar <= 1.1x) | | | | "
                  f"{m[f'bag{t}'][0] / m[f'plain{t}'][0]:.2f}x |")
        if "colortree" in m and f"colored{t}" in m:
            bar = 10 if t == 2 else 5
            print(f"| {res} | ColorOcTree / coloured, {t} thread(s) (bar >= {bar}x) | | | | "
                  f"{m['colortree'][0] / m[f'colored{t}'][0]:.2f}x |")
print()
for res, (bt1, bt2, ot1, ot2, col, colref, bagsame, *kld) in same.items():
    print(f"res {res}: .bt identical to graph2tree's: {bt1} (1 thread), {bt2} (2 threads); "
          f".ot: {ot1}, {ot2}; compare_octrees KLD: {' '.join(kld)}; "
          f"coloured .ot 1 vs 2 threads identical: {col}; coloured .ot identical to "
          f"ColorOcTree's: {colref}; bag .ot identical to the .graph's: {bagsame}")
PY
