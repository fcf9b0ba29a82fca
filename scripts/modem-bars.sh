#!/usr/bin/env bash
# The bars of issue 5, measured: modem-bench against the S100 model in virtual time, in real
# time through link-sim's pseudo-terminals, the fitted model fed back to link-sim, and the
# EvoLogics dialect end to end. Prints one table; takes about four minutes (real time).
#
# Usage: scripts/modem-bars.sh [--quick]   (--quick: 20 instead of 60 packets per size in real time)
set -euo pipefail
cd "$(dirname "$0")/.."
per_size=60
[ "${1:-}" = "--quick" ] && per_size=20
cargo build --release --quiet --bin modem-bench --bin link-sim
bin=target/release
work=$(mktemp -d)
trap 'rm -rf "$work"; jobs -p | xargs -r kill 2>/dev/null || true' EXIT
field() { python3 -c "import json,sys; v=json.load(open('$1'))$2; print('%.2f' % v if v is not None else '-')"; }

# 1. Virtual time: S100, sizes 16/57/100, 2000 packets each.
"$bin/modem-bench" --sim s100 --sizes 16,57,100 --count 2000 -q -o "$work/sim.csv" \
    --summary "$work/sim.json" --fit "$work/sim-fit.json"

# 2. Real time through link-sim --pty: 60 packets per size, 700 ms apart.
start_pty() {  # start_pty NAME ARGS...: link-sim --pty in the background, paths in $A and $B
    local name=$1; shift
    coproc LS { exec "$bin/link-sim" --pty "$@" 2>"$work/$name.err"; }
    read -r A <&"${LS[0]}"; read -r B <&"${LS[0]}"
}
start_pty s100 --model s100 --seed 7
"$bin/modem-bench" --tx "$A" --rx "$B" --sizes 16,57,100 --count "$per_size" --interval 700 -q \
    -o "$work/rt.csv" --summary "$work/rt.json" --fit "$work/rt-fit.json"
kill "$LS_PID"; wait "$LS_PID" 2>/dev/null || true

# 3. The real-time fitted model fed to link-sim: mean delay of 57-byte frames, against the preset.
python3 - "$work/f57.bin" <<'PY'
import sys
sys.path.insert(0, "scripts")
from wireframe import frame
with open(sys.argv[1], "wb") as f:
    for k in range(2000):
        f.write(frame(1, 2, bytes((k + j) & 0xFF for j in range(52))))
PY
"$bin/link-sim" --model s100 --stats "$work/ls-preset.json" <"$work/f57.bin" >/dev/null 2>&1
"$bin/link-sim" --model-file "$work/rt-fit.json" --stats "$work/ls-fit.json" <"$work/f57.bin" >/dev/null 2>&1

# 4. EvoLogics dialect end to end, S2CR burst model.
start_pty evo --model s2cr-burst --dialect evologics --seed 7
"$bin/modem-bench" --tx "$A" --rx "$B" --dialect evologics --sizes 16,57,100 --count 10 \
    --interval 1500 --timeout 8 -q -o "$work/evo.csv" --summary "$work/evo.json"
kill "$LS_PID"; wait "$LS_PID" 2>/dev/null || true

printf '%-52s %12s %12s %s\n' "bar" "measured" "target" ""
row() { printf '%-52s %12s %12s\n' "$1" "$2" "$3"; }
row "sim: fitted bit rate, bit/s" "$(field "$work/sim.json" "['fit_bitrate_bps']")" "1900 +-3%"
row "sim: fitted intrinsic delay, ms" "$(field "$work/sim.json" "['fit_intrinsic_delay_ms']")" "85 +-3"
row "sim: jitter around the fit, ms" "$(field "$work/sim.json" "['fit_jitter_ms']")" "13.2 +-10%"
row "real time ($per_size/size, 700 ms): fitted bit rate, bit/s" "$(field "$work/rt.json" "['fit_bitrate_bps']")" "1900 +-5%"
row "real time: fitted intrinsic delay, ms" "$(field "$work/rt.json" "['fit_intrinsic_delay_ms']")" "85 +-6"
row "real time: jitter around the fit, ms" "$(field "$work/rt.json" "['fit_jitter_ms']")" "(13.2)"
row "link-sim, preset s100: mean delay of 57 B, ms" "$(field "$work/ls-preset.json" "['a_to_b']['delay_ms_mean']")" ""
row "link-sim, fitted model: mean delay of 57 B, ms" "$(field "$work/ls-fit.json" "['a_to_b']['delay_ms_mean']")" "same +-3%"
row "evologics (s2cr-burst): delivered of 30" "$(field "$work/evo.json" "['delivered']")" "30"
row "evologics: mean delay, ms" "$(field "$work/evo.json" "['delay_ms_mean']")" "(see note)"
