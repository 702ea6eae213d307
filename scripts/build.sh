#!/usr/bin/env bash
# Configures (when needed) and builds nursing_bed and its test executables into <repo>/build.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="$ROOT/build"
# ROS 1 comes from Debian in /usr; a pyenv python3 earlier on PATH lacks catkin_pkg.
export PATH="/usr/bin:$PATH"
JOBS="${JOBS:-2}"

cache="$BUILD/CMakeCache.txt"
need_configure=0
if [[ ! -f "$cache" || ! -f "$BUILD/Makefile" ]]; then
  need_configure=1
elif ! grep -qxF "CMAKE_HOME_DIRECTORY:INTERNAL=$ROOT" "$cache" \
  || ! grep -qxF "PYTHON_EXECUTABLE:FILEPATH=/usr/bin/python3" "$cache" \
  || ! grep -qxF "CMAKE_BUILD_TYPE:STRING=Release" "$cache"; then
  # A cache from another source tree or with other settings: start the configuration afresh.
  echo "build: stale CMake cache, reconfiguring"
  rm -rf "$cache" "$BUILD/CMakeFiles"
  need_configure=1
fi

if [[ $need_configure -eq 1 ]]; then
  echo "build: configuring $BUILD"
  cmake -S "$ROOT" -B "$BUILD" -DPYTHON_EXECUTABLE=/usr/bin/python3 -DCMAKE_BUILD_TYPE=Release
fi

echo "build: make -j$JOBS"
make --no-print-directory -C "$BUILD" -j"$JOBS"
echo "build: make -j$JOBS tests"
make --no-print-directory -C "$BUILD" -j"$JOBS" tests
echo "build: ok"
