#!/usr/bin/env bash
# What authenticating (and encrypting) every frame costs, measured in one run against the plain
# session (issue 45): a simulated S100 hour at the automatic IPG and at the paper's 640 ms,
# plain, with --key-file and with --key-file --encrypt: frame sizes, the IPG and its ratio to
# the plain one (target <= 1.10), Table 4's throughput and delay both ways (the protocol's
# bytes; the air carries 6 more a frame), images per hour; then CPU per frame (the seal bench,
# against building a plain frame in the same run).
#
# Usage: scripts/secure-cost.sh [DURATION_S]    (default 3600)
set -euo pipefail
cd "$(dirname "$0")/.."
duration=${1:-3600}
cargo build --release --quiet --bin tdma-run
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
printf '* 000102030405060708090a0b0c0d0e0f\n' > "$work/keys"
chmod 600 "$work/keys"
for ipg in auto 640; do
    for mode in plain key encrypt; do
        case $mode in
            plain) extra=() ;;
            key) extra=(--key-file "$work/keys") ;;
            encrypt) extra=(--key-file "$work/keys" --encrypt) ;;
        esac
        target/release/tdma-run --sim --model s100 --ipg "$ipg" --duration "$duration" \
            "${extra[@]}" --metrics "$work/$ipg-$mode.json" --events "$work/$ipg-$mode.csv" \
            2>"$work/$ipg-$mode.txt"
    done
done
python3 - "$work" "$duration" <<'PY'
import csv, json, sys
work, duration = sys.argv[1], float(sys.argv[2])
def sizes(path):
    op = rov = 0
    with open(path) as f:
        for row in csv.DictReader(f):
            n = int(row["bytes"])
            if row["direction"] == "operator_to_rov":
                op = max(op, n)
            else:
                rov = max(rov, n)
    return op, rov
print(f"S100, {duration:.0f} s simulated, seed 1")
print("ipg   mode     op_B rov_B   IPG_ms  xIPG   R->O_kbps O->R_kbps R->O_delay_ms O->R_delay_ms images/h")
for ipg in ["auto", "640"]:
    base = None
    for mode in ["plain", "key", "encrypt"]:
        m = json.load(open(f"{work}/{ipg}-{mode}.json"))
        r, o = m["rov_to_operator"], m["operator_to_rov"]
        ipg_ms = o["iat_ms"]
        base = base or ipg_ms
        op, rov = sizes(f"{work}/{ipg}-{mode}.csv")
        per_h = m["images_completed"] * 3600.0 / m["duration_s"]
        print(f"{ipg:5} {mode:8} {op:4} {rov:5} {ipg_ms:8.1f} {ipg_ms/base:5.3f} {r['throughput_kbps']:9.3f} "
              f"{o['throughput_kbps']:9.3f} {r['delay_ms']:13.1f} {o['delay_ms']:13.1f} {per_h:8.1f}")
PY
echo
echo "CPU per frame (median of 9 x 20,000; x = against a plain frame's build in the same run):"
cargo bench --quiet -p rovlink-security --bench seal 2>/dev/null | column -t -s,
