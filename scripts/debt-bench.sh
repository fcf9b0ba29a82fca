#!/usr/bin/env bash
# DEBT speed (vs OpenJPEG, same run) and ROI figures. Installs what it needs when missing.
# Installs what it needs when missing (Debian packages, Python packages), builds the release
# tools, then runs scripts/debt-bench.py with the arguments given (see --help there).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
missing=()
command -v opj_compress >/dev/null || missing+=(libopenjp2-tools)
command -v cwebp >/dev/null || missing+=(webp)
command -v avifenc >/dev/null || missing+=(libavif-bin)
if [ ${#missing[@]} -gt 0 ]; then
  export DEBIAN_FRONTEND=noninteractive
  apt-get update -qq && apt-get install -y -qq "${missing[@]}"
fi
python3 -c 'import numpy, PIL' 2>/dev/null || python3 -m pip install -q numpy pillow
(cd "$here/.." && cargo build --release --quiet --bin debt-encode --bin debt-decode)
exec python3 "$here/debt-bench.py" "$@"
