#!/usr/bin/env bash
# What an edit costs to rebuild, before and after a change of layout, measured one right after
# the other on this machine. Each tree given (a checkout of this repository: the one crate of
# before the workspace, or the workspace) builds in its own empty target directory
# (TREE/target-cost); every step runs in each tree in turn before the next step starts, so a
# change in the machine's load hits both alike:
#   1. a cold `cargo build --release` (the registry's sources already fetched), then the whole
#      suite from a cold debug build: the tree's own test command without installs or lints
#      (`cargo test` in the one crate; `cargo build --workspace` and `cargo test --workspace`
#      in the workspace), its outcome printed as a row of its own;
#   2. for one file in each of wire, debt, octo and rcp: touch it, then time
#      `cargo build --release --bin debt-encode` (debt only), `cargo build --release` (every
#      tool) and `cargo test --no-run`;
#   3. the size of target/debug after the test builds.
# Prints one CSV row per measurement: tree,what,value (seconds of wall clock, or bytes). The
# machine is shared: run it when it is quiet, and read the ratios rather than the absolutes.
#
#   scripts/build-cost.sh /path/to/before /path/to/after > build-cost.csv
set -euo pipefail
[ $# -ge 1 ] || { echo "usage: scripts/build-cost.sh TREE..." >&2; exit 2; }
trees=()
for t in "$@"; do
  [ -f "$t/Cargo.toml" ] || { echo "build-cost: $t: not a checkout of this repository (no Cargo.toml)" >&2; exit 2; }
  trees+=("$(cd "$t" && pwd)")
done
log=$(mktemp)
trap 'rm -f "$log" "$log.suite" "$log.outcomes"' EXIT

now() { date +%s.%N; }
# In every tree, `prepare` (a function of the tree, may be :) then the timed command.
step() { # label, prepare, command...
  local label=$1 prepare=$2; shift 2
  local tree t0
  for tree in "${trees[@]}"; do
    export CARGO_TARGET_DIR="$tree/target-cost"
    (cd "$tree" && $prepare "$tree")
    t0=$(now)
    (cd "$tree" && "$@") >/dev/null 2>"$log" || { echo "build-cost: $label failed in $tree:" >&2; tail -5 "$log" >&2; exit 1; }
    printf '%s,%s,%.1f\n' "$(basename "$tree")" "$label" "$(echo "$(now) - $t0" | bc)"
  done
}
# The file of each layer in either layout.
file_of() { # tree, layer
  local f
  case $2 in
    wire) f=wire/frame.rs ;; debt) f=debt/encode.rs ;; octo) f=octo/tree.rs ;; rcp) f=rcp/rov.rs ;;
  esac
  if [ -d "$1/crates" ]; then echo "$1/crates/${f%%/*}/src/${f#*/}"; else echo "$1/src/$f"; fi
}
clean() { rm -rf "$1/target-cost"; }
# The suite, built cold and run; its outcome (passed / failed) goes to a row of its own.
suite() {
  local ok=passed
  if [ -d crates ]; then
    { cargo build --workspace --locked && cargo test --workspace --locked --no-fail-fast; } >"$log.suite" 2>&1 || ok=failed
  else
    cargo test --locked --no-fail-fast >"$log.suite" 2>&1 || ok=failed
  fi
  echo "$(basename "$PWD"),suite outcome,$ok" >>"$log.outcomes"
}
layer=""
touch_layer() { touch "$(file_of "$1" "$layer")"; }

echo "tree,what,value"
step "cold release build" clean cargo build --release --locked
: >"$log.outcomes"
step "suite: cold debug build and run" : suite
cat "$log.outcomes"
for layer in wire debt octo rcp; do
  if [ "$layer" = debt ]; then
    step "touch $layer: release debt-encode" touch_layer cargo build --release --locked --bin debt-encode
    step "touch $layer: release all tools" : cargo build --release --locked
  else
    step "touch $layer: release all tools" touch_layer cargo build --release --locked
  fi
  step "touch $layer: test --no-run" : cargo test --locked --no-run
done
for tree in "${trees[@]}"; do
  printf '%s,target/debug bytes,%s\n' "$(basename "$tree")" "$(du -sb "$tree/target-cost/debug" | cut -f1)"
done
