#!/usr/bin/env bash
# Equal-byte comparison of DEBT against OpenJPEG, WebP and AVIF: a table, CSV and a PNG plot.
# Installs what it needs when missing (see codec-env.sh), then runs scripts/rd-compare.py with
# the arguments given (see --help there).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
source "$here/codec-env.sh"
exec python3 "$here/rd-compare.py" "$@"
