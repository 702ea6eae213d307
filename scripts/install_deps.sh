#!/usr/bin/env bash
# Installs the Debian packages needed to build, test and run nursing_bed (ROS 1 from Debian).
# Idempotent: if every package is already installed it returns at once without touching apt.
set -euo pipefail

PACKAGES=(
  build-essential cmake
  # ROS 1 core, catkin and the test tools
  ros-core-dev catkin python3-catkin-pkg python3-rostest librostest-dev
  ros-message-generation ros-message-runtime
  # ROS libraries the nodes and nodelets use
  libnodeletlib-dev libnodeletlib-tools pluginlib-dev libtf2-ros-dev libtf2-dev
  liburdf-dev liburdfdom-dev ros-robot-state-publisher librobot-state-publisher-dev
  libdiagnostic-updater-dev libdiagnostic-msgs-dev libsensor-msgs-dev
  libvisualization-msgs-dev libgeometry-msgs-dev librosbag-dev
  # ROS command-line and Python tools
  python3-rosbag python3-rosservice python3-rostopic python3-rosnode python3-roslaunch
  python3-rospy rosbash python3-nodelet python3-std-msgs python3-sensor-msgs python3-geometry-msgs
  python3-diagnostic-msgs python3-visualization-msgs
  # numerics, config, tests, benchmarks
  libceres-dev libeigen3-dev libyaml-cpp-dev libgtest-dev libgmock-dev libbenchmark-dev
  # the tools' command lines and JSON, runtime-tunable parameters
  libcli11-dev nlohmann-json3-dev libdynamic-reconfigure-config-init-mutex-dev python3-dynamic-reconfigure
  # the formatting check (scripts/check_format.sh, .clang-format)
  clang-format
  # the Modbus TCP valve terminals of a real bed (modbus_tcp hardware, rig_emulator)
  libmodbus-dev
  # plotting for the reproduction figures
  python3-matplotlib python3-numpy python3-yaml
  # visualisation, headless
  rviz xvfb xauth
)

# Packages not yet in state "install ok installed".
installed=$(dpkg-query -W -f='${Package} ${db:Status-Abbrev}\n' "${PACKAGES[@]}" 2>/dev/null \
              | awk '$2 == "ii" { print $1 }' || true)
missing=()
for pkg in "${PACKAGES[@]}"; do
  if ! grep -qxF "$pkg" <<<"$installed"; then
    missing+=("$pkg")
  fi
done

if [[ ${#missing[@]} -eq 0 ]]; then
  echo "install_deps: all ${#PACKAGES[@]} packages already installed"
  exit 0
fi

if [[ $(id -u) -eq 0 ]]; then
  SUDO=()
elif command -v sudo >/dev/null 2>&1; then
  SUDO=(sudo)
else
  echo "install_deps: not root and no sudo; cannot install: ${missing[*]}" >&2
  exit 1
fi

echo "install_deps: installing ${#missing[@]} missing packages: ${missing[*]}"
export DEBIAN_FRONTEND=noninteractive
"${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -q </dev/null
"${SUDO[@]}" env DEBIAN_FRONTEND=noninteractive \
  apt-get install -y -q --no-install-recommends "${PACKAGES[@]}" </dev/null
echo "install_deps: done"
