#!/usr/bin/env bash
# The ROV end against the real ArduSub SITL, by hand: runs the session of tests/tdma_sitl.rs
# (ArduSub SITL from ../shared/peers/ardusub, or ROVLINK_ARDUSUB_DIR; operator <-> link-sim
# --pty <-> tdma-run --role rov --vehicle mavlink:tcpout:...; orders through a FIFO: arm +
# stabilize, a half forward stick for 14 s, neutral, goto (3, 1, 1); and the same GoTo on a
# vehicle without a position source, GPS1_TYPE 0) and prints what it measured: the arm/mode
# timeline, the forward speed, the time to target, the hold error over 15 s and the pose error.
# About two minutes (SITL boots in real time; its EKF has a position about 40 s after boot).
# Usage: scripts/ardusub-sitl.sh [--release]
set -euo pipefail
cd "$(dirname "$0")/.."
profile=()
[ "${1:-}" = "--release" ] && profile=(--release)
report="$(mktemp -t ardusub-sitl.XXXXXX.json)"
trap 'rm -f "$report"' EXIT
started=$(date +%s)
cargo build "${profile[@]}" --quiet --workspace
ROVLINK_SITL_REPORT="$report" cargo test "${profile[@]}" --quiet -p rovlink --test tools -- tdma_sitl --test-threads 2
python3 - "$report" "$(( $(date +%s) - started ))" <<'PY'
import json, sys
f = json.load(open(sys.argv[1]))
names = {0: "STABILIZE", 2: "ALT_HOLD", 4: "GUIDED", 16: "POSHOLD", 19: "MANUAL"}
print("arm/mode timeline (s after the operator started):")
for m in f["mode_timeline"]:
    print(f"  {m['t_s']:7.1f}  {'armed' if m['armed'] else 'disarmed':8}  {names.get(m['mode'], m['mode'])} ({m['mode']})")
print(f"armed after            {f['armed_after_operator_start_s']:.1f} s")
print(f"position known after   {f['position_after_operator_start_s']:.1f} s")
print(f"forward speed          {f['forward_speed_mps']:.2f} m/s (half stick; moved {f['forward_moved_m'][0]:.2f} m along the heading, {f['forward_moved_m'][1]:.2f} m across)")
print(f"GoTo distance          {f['goto_distance_m']:.2f} m")
print(f"time to target         {f['goto_to_within_0_5_m_s']:.1f} s to 0.5 m, {f['goto_to_within_0_3_m_s']:.1f} s to 0.3 m")
print(f"hold error             {f['hold_error_max_m']:.2f} m at most over the 15 s after the 0.3 m arrival ({f['hold_samples']} positions); {f['final_error_m']:.2f} m at the end")
print(f"pose error             {f['pose_error_max_m']:.3f} m at most ({f['pose_samples']} operator statuses against LOCAL_POSITION_NED)")
print(f"session                {f['test_s']:.0f} s; both tests {sys.argv[2]} s with the build")
PY
