# The parts of scripts/foxglove-studio.sh (tdma-run) and scripts/foxglove-studio-map.sh
# (octo-delta's live map) that are the same: sourced by both, from the repository's root, with
# `set -euo pipefail` in force and these set first:
#   me      the script's name, for its messages (foxglove-studio, foxglove-studio-map)
#   here    scripts/foxglove-studio (check.py, serve.py, the page, the layouts)
#   cache   where npm installs Studio (STUDIO_CACHE)
#   out     where check.py writes its screenshots and findings
# Sourcing it checks the prerequisites, installs Studio in $cache once (the lock file's hash
# names what is there), makes the work directory $work (removed at exit unless KEEP=1) and
# kills at exit every process whose id is in `pids`. See foxglove-studio.sh for what each
# script checks.

fail_setup() { echo "$me: $*" >&2; exit 2; }
command -v npm >/dev/null || fail_setup "npm not found (apt-get install nodejs npm)"
[ -x /usr/bin/chromium ] || fail_setup "/usr/bin/chromium not found (apt-get install chromium)"
python3 -c 'import playwright, mcap' 2>/dev/null || fail_setup "python3 lacks playwright or mcap (pip install playwright mcap)"

# Studio, installed once: the lock file's hash names what is in the cache.
mkdir -p "$cache"
stamp=$(sha256sum "$here/package-lock.json" | cut -c1-16)
if [ "$(cat "$cache/installed" 2>/dev/null)" != "$stamp" ]; then
  echo "$me: installing @foxglove/studio-base 1.48.0 into $cache" >&2
  started=$(date +%s)
  cp "$here/package.json" "$here/package-lock.json" "$cache/"
  npm ci --prefix "$cache" --no-audit --no-fund --loglevel=error >&2
  [ -f "$cache/node_modules/@foxglove/studio-base/assets/index.js" ] \
    || fail_setup "$cache: npm ci left no @foxglove/studio-base/assets/index.js"
  echo "$stamp" >"$cache/installed"
  echo "$me: installed in $(($(date +%s) - started)) s" >&2
fi

need_tools() { # PROFILE TOOL...: the tools in $BIN, or (BIN unset) built with cargo in PROFILE
  local profile=$1 tool
  shift
  if [ -z "${BIN:-}" ]; then
    local flags=(--quiet)
    [ "$profile" = debug ] || flags+=(--release)
    for tool in "$@"; do flags+=(--bin "$tool"); done
    cargo build "${flags[@]}"
    BIN=target/$profile
  fi
  for tool in "$@"; do
    [ -x "$BIN/$tool" ] || fail_setup "$BIN/$tool: not built"
  done
}

work=$(mktemp -d)
pids=()
cleanup() {
  for pid in "${pids[@]}"; do kill "$pid" 2>/dev/null || true; done
  wait 2>/dev/null || true
  if [ "${KEEP:-0}" = 1 ]; then echo "$me: kept $work" >&2; else rm -rf "$work"; fi
}
trap cleanup EXIT
trap 'exit 130' INT
trap 'exit 143' TERM

wait_for_file() { # PATH SECONDS WHAT: wait until PATH has a line
  local deadline=$(($(date +%s) + $2))
  until [ -s "$1" ]; do
    [ "$(date +%s)" -lt "$deadline" ] || fail_setup "$3: not seen within $2 s"
    sleep 0.2
  done
}

free_port() {
  python3 -c "import socket; s=socket.socket(); s.bind(('127.0.0.1',0)); print(s.getsockname()[1])"
}

wait_for_line() { # FILE PATTERN SECONDS WHAT PID: wait until FILE has a line with PATTERN
  local deadline=$(($(date +%s) + $3))
  until grep -q "$2" "$1"; do
    [ "$(date +%s)" -lt "$deadline" ] || fail_setup "$4: not seen within $3 s: $(tail -3 "$1")"
    kill -0 "$5" 2>/dev/null || fail_setup "$4: the process exited: $(tail -3 "$1")"
    sleep 0.1
  done
}

start_link_sim() { # ARGS...: `link-sim --pty ARGS`; its two ends in side_a and side_b
  "$BIN/link-sim" --pty "$@" >"$work/link.out" 2>"$work/link.err" &
  pids+=($!)
  local deadline=$(($(date +%s) + 10))
  until [ "$(wc -l <"$work/link.out")" -ge 2 ]; do
    [ "$(date +%s)" -lt "$deadline" ] || fail_setup "link-sim gave no pty paths: $(cat "$work/link.err")"
    sleep 0.1
  done
  side_a=$(sed -n 1p "$work/link.out")
  side_b=$(sed -n 2p "$work/link.out")
}

start_page_server() { # serves Studio's page, and $work/data (the logs) at data/; its URL in studio
  mkdir -p "$work/data"
  python3 "$here/serve.py" "$here" "$cache/node_modules" "$work/data" "$work/http.port" \
    2>"$work/http.err" &
  pids+=($!)
  wait_for_file "$work/http.port" 10 "the page server's port"
  studio="http://127.0.0.1:$(cat "$work/http.port")/"
  mkdir -p "$out"
}

status=0
check() { # NAME ARGS...: one check.py run; one that could not be made (2) stops the script
  local rc=0
  python3 "$here/check.py" "$1" --studio "$studio" --out "$out" "${@:2}" || rc=$?
  [ "$rc" -le 1 ] || exit "$rc"
  [ "$rc" = 0 ] || status=1
}

stop() { # PID ERR NAME: SIGINT (Ctrl-C), which ends a session keeping its outputs; its end
  local rc=0
  kill -INT "$1" 2>/dev/null || true
  wait "$1" || rc=$?
  [ "$rc" = 0 ] || [ "$rc" = 130 ] || fail_setup "$3 exited $rc: $(tail -3 "$2")"
}

warned_of_studio() { # NAME ERR TOKEN EXPECTED...: fails (status=1) on a `foxglove client` line
  # of ERR that matches none of EXPECTED (fixed strings), and on TOKEN said; shows the other
  # Foxglove lines
  local name=$1 err=$2 token=$3 unexpected expected
  shift 3
  local patterns=()
  for expected in "$@"; do patterns+=(-e "$expected"); done
  { grep -v "Foxglove: ws://" "$err" | grep -i "foxglove" || true; } | sed "s/^/$name: /"
  unexpected=$(grep "foxglove client" "$err" | grep -v -F "${patterns[@]}" || true)
  if [ -n "$token" ] && grep -q -F "$token" "$err"; then
    echo "$name: the control token was said on standard error"
    status=1
  fi
  if [ -n "$unexpected" ]; then
    echo "$name: warned of what Studio sent:"
    echo "$unexpected"
    status=1
  fi
}

finish() { # WHAT: the last line, and the exit status
  if [ "$status" = 0 ]; then
    echo "$me: passed: Foxglove Studio 1.48.0, $*; screenshots in $out"
  else
    echo "$me: FAILED (the lines above; everything seen in $out/*.json)"
  fi
  exit "$status"
}
