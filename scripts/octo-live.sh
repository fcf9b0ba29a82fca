#!/usr/bin/env bash
# The second paper's system, live (issue 46): octo-delta map on the "vehicle" and octo-delta view
# on the "operator" over link-sim --pty with the satellite models (768 kbit/s up, 256 kbit/s
# down, 310 ms each way), the 80-scan synthetic survey recorded as it is mapped (synth --pace
# 0.5: 2 scans per second). Five runs:
#   clean      no loss
#   loss5      5% frame loss both ways
#   outage     5% loss and 20 s out of range (t = 14 s to 34 s of link time)
#   restart    5% loss, the view killed (SIGTERM) once it shows scan 25 and started again 5 s later
#   requests   no loss; at scan 30 a full-map request, at scan 50 a ROI move (a FIFO console)
# For each: whether the view's final .ot equals `apply` of the offline `build` stream (byte for
# byte; not expected of `requests`, whose full map carries colours as they are now), the time
# from each cloud's arrival at the mapper to its voxels shown (p50/p95/max), bytes on the link
# (transport included) against the full map's size per scan (Figs. 5-7, from a real link),
# resends, and the link's use against the shaped rate; beside the simulated `build --link`
# figures of the same survey (satellite-up, and with 5% loss), with live/simulated ratios. For
# the requests: the time from asked to the answer applied against the bound "transfer time of
# the answer (its bytes at the shaped rate, plus a round trip) plus one resend timeout".
#
# Usage: scripts/octo-live.sh [OUT_DIR]   (default target/octo-live). BIN=dir of octo-delta and
# link-sim (default: a release build). Takes about 5 minutes (each run is the survey's 40 s).
# Exit 0 when every identity and bound holds, 1 otherwise.
set -euo pipefail
cd "$(dirname "$0")/.."
out=${1:-target/octo-live}
if [ -z "${BIN:-}" ]; then
    cargo build --release --quiet -p octo-delta -p link-sim
    BIN=target/release
fi
BIN=$(cd "$BIN" && pwd)
mkdir -p "$out"
out=$(cd "$out" && pwd)
od=$BIN/octo-delta
$od synth -o "$out/survey.graph"
$od build "$out/survey.graph" -q -o "$out/offline.odl" --stats "$out/offline-stats.csv" \
    --link satellite-up --scan-period 0.5 --arrivals "$out/sim-arrivals.csv" --metrics "$out/sim.json"
$od apply "$out/offline.odl" -o "$out/offline.ot"
$BIN/link-sim --model satellite-up --loss-percent 5 --print-model > "$out/satellite-up-5.json"
$od build "$out/survey.graph" -q -o "$out/offline5.odl" --link "$out/satellite-up-5.json" \
    --scan-period 0.5 --arrivals "$out/sim5-arrivals.csv" --metrics "$out/sim5.json"

# Waits (at most 300 s) for a line containing $2 in file $1.
wait_line() {
    local i=0
    until grep -q -- "$2" "$1" 2>/dev/null; do
        sleep 0.1
        i=$((i + 1))
        [ $i -lt 3000 ] || { echo "no '$2' in $1" >&2; return 1; }
    done
}

run() {
    local name=$1; shift
    local d=$out/$name
    rm -rf "$d"; mkdir -p "$d"
    local extra=()
    case $name in
        loss5|restart) extra=(--loss-percent 5) ;;
        outage)
            printf 't_s,distance_m\n0,1\n14,1\n14.001,5000\n34,5000\n34.001,1\n' > "$d/distance.csv"
            extra=(--loss-percent 5 --range-max-m 1000 --distance-file "$d/distance.csv") ;;
    esac
    $BIN/link-sim --model satellite-up --reverse-model satellite-down --pty "${extra[@]}" \
        > "$d/ptys" 2> "$d/link-sim.err" &
    local ls=$!
    wait_line "$d/ptys" /dev/ && until [ "$(wc -l < "$d/ptys")" -ge 2 ]; do sleep 0.05; done
    local a b; a=$(sed -n 1p "$d/ptys"); b=$(sed -n 2p "$d/ptys")
    local orders=()
    if [ "$name" = requests ]; then
        mkfifo -m 600 "$d/orders"
        orders=(--orders "$d/orders")
    fi
    $od synth --pace 0.5 -o "$d/live.graph" &
    local sy=$!
    $od map "$d/live.graph" --follow --port "$a" --exit-when-done --metrics "$d/map.json" \
        --stats "$d/map-stats.csv" --ot "$d/map.ot" 2> "$d/map.err" &
    local mp=$!
    if [ "$name" = restart ]; then
        $od view --port "$b" -o "$d/view-first.ot" 2> "$d/view-first.err" &
        local v1=$!
        wait_line "$d/view-first.err" "scan 25: "
        kill -TERM $v1; wait $v1 || true
        sleep 5
    fi
    $od view --port "$b" -o "$d/view.ot" --metrics "$d/view.json" --arrivals "$d/view-arrivals.csv" \
        --exit-after-scan 79 "${orders[@]}" 2> "$d/view.err" &
    local vw=$!
    if [ "$name" = requests ]; then
        exec 7> "$d/orders"
        wait_line "$d/view.err" "scan 30: delta"
        echo '{"type":"full"}' >&7
        wait_line "$d/view.err" "scan 50: delta"
        echo '{"type":"roi","box":[-6,-6,-40,6,6,0]}' >&7
    fi
    wait $vw || echo "$name: view exit $?" >&2
    wait $mp || echo "$name: map exit $?" >&2
    [ "$name" = requests ] && exec 7>&-
    kill -INT $ls 2>/dev/null; wait $ls || true
    wait $sy || true
}

for r in clean loss5 outage restart requests; do
    echo "== $r" >&2
    run "$r"
done

python3 - "$out" <<'PY'
import csv, json, sys, os
out = sys.argv[1]
ok = True

def q(v):
    v = sorted(v)
    if not v:
        return (float("nan"),) * 3
    at = lambda p: v[round((len(v) - 1) * p)]
    return at(0.5), at(0.95), v[-1]

sim = {}
for name, f in (("sim", "sim-arrivals.csv"), ("sim5", "sim5-arrivals.csv")):
    rows = list(csv.DictReader(open(os.path.join(out, f))))
    sim[name] = q([float(r["latency_s"]) for r in rows])
stats = list(csv.DictReader(open(os.path.join(out, "offline-stats.csv"))))
full_bt = sum(int(r["full_bt_bytes"]) for r in stats)
delta_bytes = sum(int(r["delta_bytes"]) for r in stats)
simj = json.load(open(os.path.join(out, "sim.json")))["link"]
offline = open(os.path.join(out, "offline.ot"), "rb").read()
print(f"survey: {len(stats)} scans; delta messages {delta_bytes} B; the full map after every scan (.bt) {full_bt} B ({full_bt / delta_bytes:.1f}x)")
print(f"simulated build --link satellite-up, 2 scans/s: latency p50 {sim['sim'][0]:.3f} s, p95 {sim['sim'][1]:.3f} s, max {sim['sim'][2]:.3f} s; link bytes {simj.get('link_bytes')}")
print(f"simulated with 5% loss: latency p50 {sim['sim5'][0]:.3f} s, p95 {sim['sim5'][1]:.3f} s, max {sim['sim5'][2]:.3f} s")
print()
print(f"{'run':9} {'same .ot':8} {'p50 s':>7} {'p95 s':>7} {'max s':>7} {'p50/sim':>7} {'link B':>8} {'link/sim':>8} {'resends':>7} {'use/rate':>8} {'B/scan':>7} {'full/scan':>9}")
for name in ("clean", "loss5", "outage", "restart", "requests"):
    d = os.path.join(out, name)
    try:
        v = json.load(open(os.path.join(d, "view.json")))
        m = json.load(open(os.path.join(d, "map.json")))
    except OSError as e:
        print(f"{name}: no figures ({e})"); ok = False; continue
    same = open(os.path.join(d, "view.ot"), "rb").read() == offline if os.path.exists(os.path.join(d, "view.ot")) else False
    if name != "requests" and not same:
        ok = False
    lat = v["latency_s"] or {}
    ref = sim["sim5" if name in ("loss5",) else "sim"]
    t = m["transport"]
    scans = m["scans"]
    link_b = t["link_bytes"]
    ratio_b = link_b / simj["link_bytes"] if simj.get("link_bytes") else float("nan")
    print(f"{name:9} {str(same):8} {lat.get('p50', float('nan')):7.3f} {lat.get('p95', float('nan')):7.3f} {lat.get('max', float('nan')):7.3f} {lat.get('p50', float('nan')) / ref[0]:7.2f} {link_b:8d} {ratio_b:8.2f} {t['resends']:7d} {t['link_use_of_rate']:8.3f} {link_b / max(scans, 1):7.0f} {full_bt / len(stats):9.0f}")
    if t["link_use_of_rate"] > 1.0:
        ok = False
    if name == "requests":
        rto = v["transport"]["rto_ms"] / 1e3
        rate = t["rate_bps"]
        for r in v["requests"]:
            if r["request"]["type"] == "resync":
                continue
            b = r.get("answer_bytes") or 0
            link_bytes = b + -(-b // 245) * 15
            bound = link_bytes * 8 / rate + 2 * 0.310 + rto
            took = (r["applied_s"] - r["asked_s"]) if r.get("applied_s") is not None else float("inf")
            good = took <= bound
            ok &= good
            print(f"  request {json.dumps(r['request'])}: answer {b} B applied {took:.3f} s after asking; bound {bound:.3f} s (transfer {link_bytes * 8 / rate + 0.62:.3f} s + resend timeout {rto:.3f} s): {'within' if good else 'OVER'}")
print()
print("within 10% of the simulated latency (clean, p50):", end=" ")
try:
    v = json.load(open(os.path.join(out, "clean", "view.json")))
    r = v["latency_s"]["p50"] / sim["sim"][0]
    print(f"{r:.3f}", "yes" if abs(r - 1) <= 0.10 else "NO")
    ok &= abs(r - 1) <= 0.10
except Exception as e:
    print("n/a", e); ok = False
sys.exit(0 if ok else 1)
PY
