#!/usr/bin/env bash
# DEBT speed against OpenJPEG measured in the same run, and ROI figures. Installs what it needs
# when missing (see codec-env.sh), then runs scripts/debt-bench.py with the arguments given.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
source "$here/codec-env.sh"
exec python3 "$here/debt-bench.py" "$@"
