#!/usr/bin/env bash
# The loss trade-off of segmented DEBT streams (see scripts/debt-loss.py --help).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
python3 -c 'import numpy, PIL' 2>/dev/null || python3 -m pip install -q numpy pillow
(cd "$here/.." && cargo build --release --quiet --bin debt-encode --bin debt-decode)
exec python3 "$here/debt-loss.py" "$@"
