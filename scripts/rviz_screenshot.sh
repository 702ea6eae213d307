#!/usr/bin/env bash
# Takes a screenshot of rviz showing the running bed, headless (Xvfb, software OpenGL).
#   scripts/rviz_screenshot.sh OUT.png [SECONDS] [RVIZ_CONFIG]
# SECONDS: how long rviz runs before the shot (default 12: it must load 180 meshes and TF).
# RVIZ_CONFIG: default <package>/config/bed.rviz.
# Needs a ROS master with robot_description and TF already running, e.g.
#   roslaunch nursing_bed sim.launch &   (started by the caller; this script does not stop it)
# Starts Xvfb on :99 unless one runs there already, and stops only what it started.
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
# ROS 1 comes from Debian in /usr; a pyenv python3 earlier on PATH lacks rospy.
export PATH="/usr/bin:$PATH"
DISPLAY_NUM=99

usage() {
  echo "usage: $0 OUT.png [SECONDS] [RVIZ_CONFIG]" >&2
  exit 2
}

[[ $# -ge 1 && $# -le 3 ]] || usage
OUT="$1"
SECONDS_TO_RUN="${2:-12}"
CONFIG="${3:-$ROOT/config/bed.rviz}"
[[ "$OUT" == *.png ]] || { echo "rviz_screenshot: OUT must end in .png: $OUT" >&2; exit 2; }
[[ "$SECONDS_TO_RUN" =~ ^[0-9]+$ && "$SECONDS_TO_RUN" -ge 1 ]] \
  || { echo "rviz_screenshot: SECONDS must be a positive integer: $SECONDS_TO_RUN" >&2; exit 2; }
[[ -r "$CONFIG" ]] || { echo "rviz_screenshot: no such rviz config: $CONFIG" >&2; exit 2; }
command -v rviz >/dev/null || { echo "rviz_screenshot: rviz not installed (scripts/install_deps.sh)" >&2; exit 1; }
command -v Xvfb >/dev/null || { echo "rviz_screenshot: Xvfb not installed (scripts/install_deps.sh)" >&2; exit 1; }

# rviz without a master waits forever and shows an empty scene: fail at once instead.
if ! /usr/bin/python3 -c 'import sys, rosgraph; sys.exit(0 if rosgraph.is_master_online() else 1)' 2>/dev/null; then
  echo "rviz_screenshot: no ROS master at ${ROS_MASTER_URI:-http://localhost:11311}; start the bed first" >&2
  exit 1
fi

apt_install() {
  local sudo=()
  if [[ $(id -u) -ne 0 ]]; then
    command -v sudo >/dev/null || { echo "rviz_screenshot: need $*, not root and no sudo" >&2; exit 1; }
    sudo=(sudo)
  fi
  echo "rviz_screenshot: installing $*"
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends "$@" </dev/null >/dev/null
}
# xwd grabs the root window; convert turns XWD into PNG. A `convert` that is not ImageMagick
# (some machines have a stand-in) cannot read XWD.
command -v xwd >/dev/null || apt_install x11-apps
convert -version 2>/dev/null | grep -q ImageMagick || apt_install imagemagick
convert -version 2>/dev/null | grep -q ImageMagick \
  || { echo "rviz_screenshot: convert is still not ImageMagick's ($(command -v convert))" >&2; exit 1; }

WORK="$(mktemp -d /tmp/rviz_screenshot.XXXXXX)"
XVFB_PID=""
RVIZ_PID=""

stop() {  # stop PID: TERM, then KILL if it lingers
  local pid="$1" i
  kill "$pid" 2>/dev/null || return 0
  for i in $(seq 20); do
    kill -0 "$pid" 2>/dev/null || return 0
    sleep 0.1
  done
  kill -9 "$pid" 2>/dev/null || true
}
cleanup() {
  [[ -n "$RVIZ_PID" ]] && stop "$RVIZ_PID"
  [[ -n "$XVFB_PID" ]] && stop "$XVFB_PID"
  rm -rf "$WORK"
}
trap cleanup EXIT
trap 'exit 130' INT TERM

# Reuse a live X server on :99 (the lock file names its pid), else start our own.
lock="/tmp/.X${DISPLAY_NUM}-lock"
if [[ -e "$lock" ]] && kill -0 "$(tr -d ' ' <"$lock")" 2>/dev/null; then
  echo "rviz_screenshot: using the X server already on :$DISPLAY_NUM"
else
  Xvfb ":$DISPLAY_NUM" -screen 0 1280x800x24 -nolisten tcp >"$WORK/xvfb.log" 2>&1 &
  XVFB_PID=$!
  for _ in $(seq 50); do
    [[ -S "/tmp/.X11-unix/X$DISPLAY_NUM" ]] && break
    kill -0 "$XVFB_PID" 2>/dev/null || { echo "rviz_screenshot: Xvfb died:" >&2; cat "$WORK/xvfb.log" >&2; exit 1; }
    sleep 0.1
  done
  [[ -S "/tmp/.X11-unix/X$DISPLAY_NUM" ]] || { echo "rviz_screenshot: Xvfb did not come up" >&2; exit 1; }
fi

# __name keeps this rviz from clashing with one a launch file may have started.
LIBGL_ALWAYS_SOFTWARE=1 DISPLAY=":$DISPLAY_NUM" rviz -d "$CONFIG" __name:="rviz_screenshot_$$" \
  >"$WORK/rviz.log" 2>&1 &
RVIZ_PID=$!
for _ in $(seq "$SECONDS_TO_RUN"); do
  sleep 1
  if ! kill -0 "$RVIZ_PID" 2>/dev/null; then
    RVIZ_PID=""
    echo "rviz_screenshot: rviz exited early; its output:" >&2
    tail -n 30 "$WORK/rviz.log" >&2
    exit 1
  fi
done

xwd -root -silent -display ":$DISPLAY_NUM" >"$WORK/screen.xwd"
mkdir -p "$(dirname "$OUT")"
convert "xwd:$WORK/screen.xwd" "$WORK/screen.png"
mv "$WORK/screen.png" "$OUT"
echo "rviz_screenshot: wrote $OUT"
