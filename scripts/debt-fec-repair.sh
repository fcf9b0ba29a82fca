#!/usr/bin/env bash
# Issue 48: how long debt-decode takes to repair a stream with parity whose header trunk was
# lost, release build. Encodes uieb-616 (1280x720, from ../shared/testdata/images; not
# redistributable, read in place) to a 2,000,000-byte stream with 50 % parity in 16-byte trunks
# (125,000 trunks), loses 22,000 of them (0-21999: the header's among them; 1-22000: not) and
# prints:
#   - the repair alone (examples/fec_repair_time: rovlink_debt::fec::repair, fastest of 5);
#   - debt-decode's whole run to PPM (fastest of 3), the picture checked identical to the whole
#     stream's; its decoding without any loss is the baseline;
#   - the issue's hostile inputs: 131,070 random bytes in 1-byte trunks with the first 80 lost,
#     and with trunk 0 named 64,000 times (each ends with exit 2, "the header was lost").
# With --old PATH, each debt-decode run is also timed once with that binary (e.g. a build of the
# commit before issue 48: 35-105 s a run there).
#
# Usage: scripts/debt-fec-repair.sh [--old PATH]
#   (builds the release tools and the example into ${CARGO_TARGET_DIR:-target})
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
old=""
while [ $# -gt 0 ]; do
  case "$1" in
    --old) old="$2"; shift 2 ;;
    *) echo "usage: $0 [--old PATH]" >&2; exit 2 ;;
  esac
done
images="$root/../shared/testdata/images"
target="${CARGO_TARGET_DIR:-$root/target}"
(cd "$root" && cargo build -q --release -p debt-encode -p debt-decode &&
  cargo build -q --release -p rovlink-debt --example fec_repair_time)
enc="$target/release/debt-encode"
dec="$target/release/debt-decode"
probe="$target/release/examples/fec_repair_time"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT

# Seconds taken by the fastest of N runs of a command (its output and exit code ignored).
fastest() {
  local runs=$1 best=""
  shift
  for _ in $(seq "$runs"); do
    local t0 t1
    t0=$(date +%s.%N)
    "$@" >/dev/null 2>&1 || true
    t1=$(date +%s.%N)
    best=$(awk -v a="$best" -v b="$(awk -v s="$t0" -v e="$t1" 'BEGIN { print e - s }')" \
      'BEGIN { if (a == "" || b < a) print b; else print a }')
  done
  printf '%.2f s' "$best"
}

"$enc" "$images/uieb-616.png" --bytes 2000000 --fec 50 --trunk-size 16 -o "$tmp/s.debt"
"$dec" "$tmp/s.debt" -o "$tmp/whole.ppm"
head -c 131070 /dev/urandom >"$tmp/noise.bin"
with_header="$(seq -s, 0 21999)"
without_header="$(seq -s, 1 22000)"
zeros="$(printf '0,%.0s' $(seq 64000))"
zeros="${zeros%,}"

echo "repair alone (fec::repair), 2,000,000-byte stream, --fec 50 --trunk-size 16:"
for erase in 0-21999 1-22000 0; do
  echo "  --erase $erase: $("$probe" "$tmp/s.debt" 16 "$erase" 5 | sed 's/.*repair \([0-9.]* ms\).*/\1/')"
done

echo "debt-decode, the whole run to PPM (fastest of 3; --old: one run):"
while IFS='|' read -r name input args; do
  # shellcheck disable=SC2086 # the arguments are words
  line="  $name: $(fastest 3 "$dec" "$tmp/$input" $args -o "$tmp/out.ppm")"
  if [ "$input" = s.debt ]; then
    # shellcheck disable=SC2086
    "$dec" "$tmp/$input" $args -o "$tmp/out.ppm"
    cmp -s "$tmp/out.ppm" "$tmp/whole.ppm" || line="$line  (picture DIFFERS)"
  fi
  if [ -n "$old" ]; then
    # shellcheck disable=SC2086
    line="$line; --old: $(fastest 1 "$old" "$tmp/$input" $args -o "$tmp/old.ppm")"
  fi
  echo "$line"
done <<EOF
2 MB, nothing lost|s.debt|
2 MB, 22,000 trunks lost with the header|s.debt|--trunk-size 16 --erase $with_header
2 MB, 22,000 trunks lost, not the header|s.debt|--trunk-size 16 --erase $without_header
131,070 random bytes, 1-byte trunks, 0..79 lost|noise.bin|--trunk-size 1 --erase $(seq -s, 0 79)
131,070 random bytes, 1-byte trunks, 64,000 x 0|noise.bin|--trunk-size 1 --erase $zeros
EOF
