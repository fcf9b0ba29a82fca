#!/usr/bin/env bash
# Every speed figure of the toolkit against its anchor measured in the same run (issue 32):
#
#   session  an hour of the default single-vehicle session, the 3-node relay scenario's hour, a
#            simulated week, and peak memory, against the previous release of our own tdma-run
#            (scripts/tdma-speed.sh --against);
#   octree   octo-delta build of a 40-scan survey at 0.1 m, 1 and 2 threads, plain and coloured,
#            against OctoMap's graph2tree, with the maps compared byte for byte; the same scans
#            as a zstd MCAP bag against the .graph (bar: <= 1.1x), and the coloured build against
#            OctoMap's own ColorOcTree fed the same clouds (bars: >= 10x on 2 threads, >= 5x on
#            1), its .ot compared byte for byte (scripts/octo-bench.sh);
#   debt     debt-encode / debt-decode against OpenJPEG on the bench picture
#            (scripts/debt-bench.sh, quiet-gated);
#   pty      link-sim --pty's real-time lateness at the far program (scripts/pty-latency.py; the
#            anchor is the schedule itself: issue 4's bar is p99 <= 2 ms).
#
# Medians of at least RUNS runs (default 5), interleaved with the anchor so that a shared
# machine's load hits both alike; read the ratios, not the absolute times, on a busy machine.
#
# The previous release's tdma-run is built from git revision REV (default: main before issue
# 32's work) in a temporary worktree, once: it is kept under target/speed-baseline/<commit>/.
#
# Usage: scripts/speed.sh [--runs N] [--baseline REV] [--only session|octree|debt|pty]...
# Needs: graph2tree and compare_octrees (apt-get install octomap-tools), g++ and liboctomap-dev
# (the ColorOcTree anchor), OpenJPEG's tools (installed by scripts/codec-env.sh when missing),
# python3 with numpy, Pillow, mcap and rosbags (scripts/test installs them all).
set -euo pipefail
cd "$(dirname "$0")/.."
runs=5
baseline=ca846a42912764b94203de44e69397c74aa5317d
only=()
while [ $# -gt 0 ]; do
    case $1 in
        --runs) runs=$2; shift 2 ;;
        --baseline) baseline=$2; shift 2 ;;
        --only) only+=("$2"); shift 2 ;;
        -h|--help) sed -n '2,/^set -euo/p' "$0" | sed '$d; s/^# \{0,1\}//'; exit 0 ;;
        *) echo "speed.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
    esac
done
case $runs in
    ''|*[!0-9]*) echo "speed.sh: --runs: expected a whole number >= 5, found '$runs'" >&2; exit 2 ;;
esac
[ "$runs" -ge 5 ] || { echo "speed.sh: --runs: expected at least 5 (medians of 5), found $runs" >&2; exit 2; }
commit=$(git rev-parse --verify --quiet "$baseline^{commit}") \
    || { echo "speed.sh: --baseline: '$baseline' is not a commit of this repository" >&2; exit 2; }
wanted() { [ ${#only[@]} -eq 0 ] || [[ " ${only[*]} " == *" $1 "* ]]; }

# The previous release's binaries, built once per commit.
baseline_bin() {
    local dir tree
    dir=target/speed-baseline/$commit
    if [ ! -x "$dir/tdma-run" ]; then
        echo "building the baseline ${commit:0:10} (once; kept in $dir)" >&2
        tree=$(mktemp -d)
        git worktree add --quiet --detach "$tree" "$commit"
        CARGO_TARGET_DIR=$PWD/target/speed-baseline/build \
            cargo build --release --quiet --manifest-path "$tree/Cargo.toml" --bin tdma-run
        mkdir -p "$dir"
        cp target/speed-baseline/build/release/tdma-run "$dir/"
        git worktree remove --force "$tree"
    fi
    echo "$dir"
}

cargo build --release --quiet --bins
base=$(baseline_bin)
echo "speed: $(git rev-parse --short HEAD) against baseline $(basename "$base" | cut -c1-10); $(nproc) cores; load now $(cut -d' ' -f1-3 /proc/loadavg); medians of $runs"
if wanted session; then
    echo
    echo "## session (tdma-run, whole process)"
    scripts/tdma-speed.sh --against "$base/tdma-run" --week --week-runs "$runs" "$runs"
fi
if wanted octree; then
    echo
    echo "## octree (octo-delta build against graph2tree)"
    scripts/octo-bench.sh --scans 40 --res 0.1 --runs "$runs" --table
fi
if wanted debt; then
    echo
    echo "## debt (against OpenJPEG)"
    scripts/debt-bench.sh --runs "$((runs < 9 ? 9 : runs))" --no-roi --quiet-gate --gate-timeout 20
fi
if wanted pty; then
    echo
    echo "## link-sim --pty (lateness at the far program)"
    python3 scripts/pty-latency.py --link-sim target/release/link-sim
fi
