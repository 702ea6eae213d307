#!/usr/bin/env bash
# The one run command: installs the dependencies, builds, then runs the main job.
# Extra arguments are passed on to the main job.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
BUILD="$ROOT/build"
export PATH="/usr/bin:$PATH"
cd "$ROOT"

# The main job: the simulated bed (launch args such as rows:=4 cols:=3 rviz:=true pass through).
# The paper reproduction is devel/lib/nursing_bed/paper_reproduction --out DIR.
MAIN_JOB=(roslaunch nursing_bed sim.launch)

mkdir -p "$BUILD"
echo "run_sim: installing dependencies (log: build/install_deps.log)"
if ! bash "$ROOT/scripts/install_deps.sh" >"$BUILD/install_deps.log" 2>&1 </dev/null; then
  tail -n 80 "$BUILD/install_deps.log"; echo "run_sim: installing dependencies failed" >&2; exit 1
fi
echo "run_sim: building (log: build/build.log)"
if ! bash "$ROOT/scripts/build.sh" >"$BUILD/build.log" 2>&1 </dev/null; then
  tail -n 80 "$BUILD/build.log"; echo "run_sim: build failed" >&2; exit 1
fi

# catkin's setup scripts read unset variables.
set +u
# shellcheck disable=SC1091
source "$ROOT/devel/setup.bash"
set -u

echo "run_sim: ${MAIN_JOB[*]} $*"
exec "${MAIN_JOB[@]}" "$@"
