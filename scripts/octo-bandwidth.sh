#!/usr/bin/env bash
# The second paper's Figs. 5-7: bytes sent per scan when the whole OctoMap is sent after every
# scan (.bt, as in Fig. 5) against octo-delta's changes (Fig. 6), at 10 and 15 cm, on the
# explore-then-revisit survey; Fig. 7 is the direct comparison at 15 cm. Writes
#   OUT/bandwidth-0.1.csv, OUT/bandwidth-0.15.csv   octo-delta build --stats rows
#   OUT/fig5-full.png, OUT/fig6-delta.png, OUT/fig7-compare.png
# and prints the totals and the revisit figures (the last scans, over mapped ground).
#
# Usage: scripts/octo-bandwidth.sh [OUT_DIR] [INPUT...]   (default OUT_DIR: octo-bandwidth/;
#        default input: octo-delta's synthetic survey). Needs python3 with matplotlib (installed
#        with pip when missing).
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-octo-bandwidth}
[ $# -gt 0 ] && shift
cargo build --release --quiet --bin octo-delta
python3 -c "import matplotlib" 2>/dev/null || python3 -m pip install --quiet matplotlib
mkdir -p "$out"
inputs=("$@")
if [ ${#inputs[@]} -eq 0 ]; then
    target/release/octo-delta synth -o "$out/survey.graph"
    inputs=("$out/survey.graph")
fi
for res in 0.1 0.15; do
    target/release/octo-delta build "${inputs[@]}" --res "$res" -q -o "$out/deltas-$res.odl" \
        --stats "$out/bandwidth-$res.csv"
done
python3 - "$out" <<'PY'
import csv, sys
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
out = sys.argv[1]
data = {r: list(csv.DictReader(open(f"{out}/bandwidth-{r}.csv"))) for r in ("0.1", "0.15")}
col = lambda rows, k: [int(x[k]) for x in rows]
def fig(name, title, series):
    plt.figure(figsize=(8, 4))
    for label, rows, key, style in series:
        plt.plot(col(rows, "scan"), [v / 1024 for v in col(rows, key)], style, label=label)
    plt.xlabel("scan")
    plt.ylabel("KiB sent after the scan")
    plt.title(title)
    plt.grid(alpha=0.3)
    plt.legend()
    plt.tight_layout()
    plt.savefig(f"{out}/{name}")
    plt.close()
fig("fig5-full.png", "Full OctoMap (.bt) after every scan",
    [("10 cm", data["0.1"], "full_bt_bytes", "r-"), ("15 cm", data["0.15"], "full_bt_bytes", "b-")])
fig("fig6-delta.png", "octo-delta: changes only",
    [("10 cm", data["0.1"], "delta_bytes", "k-"), ("15 cm", data["0.15"], "delta_bytes", "-")])
fig("fig7-compare.png", "15 cm: changes vs full map",
    [("octo-delta", data["0.15"], "delta_bytes", "-"), ("full .bt", data["0.15"], "full_bt_bytes", "b-")])
print("| res | scans | delta total KiB | full .bt total KiB | ratio | fine voxels sent | bytes/voxel | revisit: max delta / full .bt |")
print("|---|---|---|---|---|---|---|---|")
for r, rows in data.items():
    d, f = sum(col(rows, "delta_bytes")), sum(col(rows, "full_bt_bytes"))
    v = sum(col(rows, "fine_occupied")) + sum(col(rows, "fine_free"))
    # The revisit: the last 30 % of the scans (the survey's default), skipping the first two
    # (the turn onto the revisit lanes still sees some new ground).
    tail = rows[int(len(rows) * 0.7) + 2:]
    worst = max(int(x["delta_bytes"]) / int(x["full_bt_bytes"]) for x in tail) if tail else float("nan")
    print(f"| {r} | {len(rows)} | {d / 1024:.1f} | {f / 1024:.1f} | {f / max(d, 1):.0f}x | {v} | {d / max(v, 1):.2f} | {100 * worst:.2f} % |")
print(f"plots: {out}/fig5-full.png {out}/fig6-delta.png {out}/fig7-compare.png")
PY
