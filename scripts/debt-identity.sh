#!/usr/bin/env bash
# Bit-identity check for refactors of the DEBT codec: encodes a fixed set of cases (colour and
# grey test images at several budgets, lossless, --gray, --scale 1, --roi, --segments 4,
# version 5's features: --restore, chroma from luma (the default from 4000 B) and --no-cfl,
# context priors (the default for lossy streams) and --no-priors, --fec parity trunks),
# decodes each (as PNM, so that no PNG writer is involved), and prints one sha256 per stream
# and per decoded picture. Run it before and after a change that must not alter the bytes and
# compare the outputs (e.g. `diff <(scripts/debt-identity.sh) before.txt`).
#
# Usage: scripts/debt-identity.sh   (uses target/release/debt-encode and debt-decode)
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
images="$root/../shared/testdata/images"
enc="$root/target/release/debt-encode"
dec="$root/target/release/debt-decode"
tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT

cases=(
  "colour-300|kodim05.png|--bytes 300"
  "colour-2000|kodim05.png|--bytes 2000"
  "colour-6000|kodim05.png|--bytes 6000"
  "colour-50000|kodim05.png|--bytes 50000"
  "uieb616-6000|uieb-616.png|--bytes 6000"
  "grey-300|boats-gray.png|--bytes 300"
  "grey-2000|boats-gray.png|--bytes 2000"
  "grey-6000|boats-gray.png|--bytes 6000"
  "grey-50000|boats-gray.png|--bytes 50000"
  "colour-lossless|kodim05.png|--lossless --bytes 100000000"
  "grey-lossless|boats-gray.png|--lossless --bytes 100000000"
  "colour-gray-2000|kodim05.png|--gray --bytes 2000"
  "colour-scale1-2000|kodim05.png|--scale 1 --bytes 2000"
  "grey-scale1-2000|boats-gray.png|--scale 1 --bytes 2000"
  "colour-roi-1000|kodim05.png|--roi 200,100,500,400 --roi-shift 4 --bytes 1000"
  "grey-roi-lossless|boats-gray.png|--roi 100,100,300,300 --lossless --bytes 100000000"
  "colour-seg4-2000|kodim05.png|--segments 4 --bytes 2000"
  "grey-seg4-6000|boats-gray.png|--segments 4 --trunk-size 39 --bytes 6000"
  "colour-nocfl-6000|kodim05.png|--no-cfl --bytes 6000"
  "colour-v1-2000|kodim05.png|--no-priors --bytes 2000"
  "grey-v1-6000|boats-gray.png|--no-priors --bytes 6000"
  "colour-fec15-2000|kodim05.png|--fec 15 --trunk-size 39 --bytes 2000"
  "grey-fec10-8000|boats-gray.png|--fec 10 --trunk-size 39 --bytes 8000"
  "colour-v3-4000|kodim05.png|--restore --bytes 4000"
  "grey-v3-8000|boats-gray.png|--restore --bytes 8000"
  "colour-v3-roi-6000|kodim05.png|--restore --roi 200,100,500,400 --bytes 6000"
)
for case in "${cases[@]}"; do
  IFS='|' read -r name image opts <<<"$case"
  # shellcheck disable=SC2086 # the options are words
  "$enc" "$images/$image" $opts -o "$tmp/$name.debt"
  "$dec" "$tmp/$name.debt" -o "$tmp/$name.pnm"
  printf '%-20s stream %s  picture %s\n' "$name" \
    "$(sha256sum <"$tmp/$name.debt" | cut -c1-16)" "$(sha256sum <"$tmp/$name.pnm" | cut -c1-16)"
done
