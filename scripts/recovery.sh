#!/usr/bin/env bash
# The paper's Figs. 12-14 scenario: the buoy (operator's modem) at the origin, the ROV starting
# at 1,0,1 m, a GoTo to 2,0,1 at 5 s, then one to 8,0,1 at 40 s, past the S100's 5 m range. The
# ROV loses the link, backtracks through its stacked positions until heartbeats return, and
# holds there. Plots against time, as PNG:
#   recovery-distance.png   distance buoy-ROV, distance buoy-target, the 5 m range (Fig. 12)
#   recovery-backtrack.png  the stacked position being recovered while the link is lost (Fig. 13)
#   recovery-positions.png  target and actual N, E, D positions (Fig. 14)
# and prints the link losses and recoveries. Needs python3 with matplotlib (installed with pip
# when missing).
#
# Usage: scripts/recovery.sh [OUT_DIR] [-- extra tdma-run options]   (default OUT_DIR: recovery/,
#        default link: S100 at BER 7e-4 as in the paper's experiment)
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-recovery}
[ $# -gt 0 ] && shift
[ "${1:-}" = "--" ] && shift
cargo build --release --quiet --bin tdma-run
python3 -c "import matplotlib" 2>/dev/null || python3 -m pip install --quiet matplotlib
mkdir -p "$out"
printf 't_s,x_m,y_m,z_m,heading_deg\n5,2,0,1,0\n40,8,0,1,0\n' > "$out/waypoints.csv"
target/release/tdma-run --sim --model s100 --ber 7e-4 --buoy 0,0,0 --start 1,0,1 --duration 200 \
    --waypoints "$out/waypoints.csv" --track "$out/track.csv" --metrics "$out/metrics.json" \
    --mcap "$out/session.mcap" "$@" 2>"$out/summary.txt"
python3 - "$out" <<'PY'
import csv, json, sys
import matplotlib
matplotlib.use("Agg")
import matplotlib.pyplot as plt
out = sys.argv[1]
rows = list(csv.DictReader(open(f"{out}/track.csv")))
num = lambda v: float(v) if v != "" else None
t = [float(r["t_s"]) for r in rows]
distance = [float(r["distance_m"]) for r in rows]
# The target is the last GoTo the ROV received: held after the ROV abandons it on link loss.
goal, last = [], None
for r in rows:
    if r["goal_distance_m"] != "":
        last = (float(r["goal_distance_m"]), [float(r[f"goal_{a}_m"]) for a in "xyz"])
    goal.append(last)
lost = [r["link_up"] == "0" for r in rows]

def shade(ax):
    start = None
    for k, is_lost in enumerate(lost + [False]):
        if is_lost and start is None:
            start = t[k]
        elif not is_lost and start is not None:
            ax.axvspan(start, t[k - 1], color="0.9", label="link lost" if start == next(
                t[j] for j in range(len(lost)) if lost[j]) else None)
            start = None

fig, ax = plt.subplots(figsize=(8, 4))
shade(ax)
ax.plot(t, distance, label="distance buoy - ROV")
ax.plot(t, [g[0] if g else None for g in goal], "--", label="distance buoy - target")
ax.axhline(5.0, color="red", linestyle=":", label="S100 range (5 m)")
ax.set(xlabel="time (s)", ylabel="distance (m)", title="Distance between the modems (Fig. 12)")
ax.legend(loc="upper left"); fig.tight_layout(); fig.savefig(f"{out}/recovery-distance.png", dpi=110)

fig, ax = plt.subplots(figsize=(8, 4))
shade(ax)
for axis, name in zip("xyz", ("north", "east", "down")):
    ax.plot(t, [num(r[f"backtrack_{axis}_m"]) for r in rows], ".", markersize=3,
            label=f"position being recovered: {name}")
ax.set(xlabel="time (s)", ylabel="m", title="Stacked positions recovered while the link is lost (Fig. 13)")
ax.legend(loc="upper left"); fig.tight_layout(); fig.savefig(f"{out}/recovery-backtrack.png", dpi=110)

fig, axes = plt.subplots(3, 1, figsize=(8, 7), sharex=True)
for k, (axis, name) in enumerate(zip("xyz", ("north", "east", "down"))):
    shade(axes[k])
    axes[k].plot(t, [float(r[f"{axis}_m"]) for r in rows], label="actual")
    axes[k].plot(t, [g[1][k] if g else None for g in goal], "--", label="target")
    axes[k].set_ylabel(f"{name} (m)")
axes[0].set_title("Target and actual NED positions (Fig. 14)")
axes[0].legend(loc="upper left"); axes[2].set_xlabel("time (s)")
fig.tight_layout(); fig.savefig(f"{out}/recovery-positions.png", dpi=110)

m = json.load(open(f"{out}/metrics.json"))
first_loss = next((t[k] for k in range(len(t)) if lost[k]), None)
regained = next((t[k] for k in range(len(t)) if first_loss and t[k] > first_loss and not lost[k]), None)
print(f"link lost {m['link_losses']} time(s), recovered {m['link_recoveries']} time(s); "
      f"first lost at {first_loss} s at {distance[t.index(first_loss)]:.2f} m, regained at {regained} s "
      f"at {distance[t.index(regained)]:.2f} m; final distance {distance[-1]:.2f} m")
print(f"plots: {out}/recovery-distance.png {out}/recovery-backtrack.png {out}/recovery-positions.png")
PY
