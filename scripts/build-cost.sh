#!/usr/bin/env bash
# What an edit costs to rebuild, before and after a change of layout, measured one right after
# the other on this machine: for each tree given (a checkout of this repository, either the one
# crate of before the workspace or the workspace), with its own empty target directory,
#   1. a cold `cargo build --release` (the registry's sources already fetched);
#   2. for one file in each of wire, debt, octo and rcp: touch it, then time
#      `cargo build --release` (every tool), `cargo build --release --bin debt-encode` for debt,
#      and `cargo test --no-run` (every test binary, debug);
#   3. the size of target/debug after the test build.
# Prints one CSV row per measurement: tree,what,seconds (or bytes). Wall-clock seconds; the
# machine is shared, so run it when it is quiet and read the ratios, not the absolutes.
#
#   scripts/build-cost.sh /work/before /work/after > build-cost.csv
set -euo pipefail
[ $# -ge 1 ] || { echo "usage: scripts/build-cost.sh TREE..." >&2; exit 2; }

now() { date +%s.%N; }
timed() { # label, command...
  local label=$1; shift
  local t0; t0=$(now)
  "$@" >/dev/null 2>"$log" || { echo "build-cost: $label failed, see $log" >&2; exit 1; }
  printf '%s,%s,%.1f\n' "$name" "$label" "$(echo "$(now) - $t0" | bc)"
}
# The file of each layer in either layout.
file_of() { # tree, layer
  case $2 in
    wire) f=wire/frame.rs ;; debt) f=debt/encode.rs ;; octo) f=octo/tree.rs ;; rcp) f=rcp/rov.rs ;;
  esac
  if [ -d "$1/crates" ]; then echo "$1/crates/${f%%/*}/src/${f#*/}"; else echo "$1/src/$f"; fi
}

echo "tree,what,value"
for tree in "$@"; do
  name=$(basename "$tree")
  export CARGO_TARGET_DIR="$tree/target-cost"
  log=$(mktemp)
  rm -rf "$CARGO_TARGET_DIR"
  cd "$tree"
  timed "cold release build" cargo build --release --locked
  timed "cold test build (--no-run)" cargo test --locked --no-run
  for layer in wire debt octo rcp; do
    file=$(file_of "$tree" "$layer")
    touch "$file"
    if [ "$layer" = debt ]; then
      timed "touch $layer: release debt-encode" cargo build --release --locked --bin debt-encode
    fi
    timed "touch $layer: release all tools" cargo build --release --locked
    timed "touch $layer: test --no-run" cargo test --locked --no-run
  done
  printf '%s,target/debug bytes,%s\n' "$name" "$(du -sb "$CARGO_TARGET_DIR/debug" | cut -f1)"
done
