#!/usr/bin/env bash
# The one test command: installs the dependencies, builds, runs every test.
# Logs go to build/*.log; the last line printed is "N passed, N failed".
set -uo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="$ROOT/build"
export PATH="/usr/bin:$PATH"
mkdir -p "$BUILD"

fail() {  # <step> <log>
  if grep -qE 'error:|Error [0-9]|CMake Error' "$2"; then
    echo "--- errors in $2:"
    grep -E -A3 'error:|CMake Error' "$2" | head -n 60
    echo "--- end of $2:"
  fi
  tail -n 30 "$2"
  echo "test: $1 failed (full log: $2)"
  echo
  echo "0 passed, 1 failed"
  exit 1
}

echo "test: installing dependencies (log: build/install_deps.log)"
bash "$ROOT/scripts/install_deps.sh" >"$BUILD/install_deps.log" 2>&1 </dev/null \
  || fail "installing dependencies" "$BUILD/install_deps.log"
tail -n 1 "$BUILD/install_deps.log"

echo "test: building (log: build/build.log)"
start=$SECONDS
bash "$ROOT/scripts/build.sh" >"$BUILD/build.log" 2>&1 </dev/null || fail "build" "$BUILD/build.log"
echo "test: build ok in $((SECONDS - start)) s"

NB_SKIP_BUILD=1 exec bash "$ROOT/scripts/run_tests.sh" </dev/null
