# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0
#
# Source this from the repository root after `make build` to use the workspace in a shell:
#   source tools/env.sh
# It activates the venv holding the ROS 2 Jazzy wheels and overlays the colcon install space,
# like `source /opt/ros/jazzy/setup.bash && source install/setup.bash` on a full ROS install.
_wctls_root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
# shellcheck disable=SC1091
source "$_wctls_root/.venv/bin/activate"
export AMENT_PREFIX_PATH="$_wctls_root/.venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
export CMAKE_PREFIX_PATH="$_wctls_root/.venv${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
if [ -f "$_wctls_root/install/setup.bash" ]; then
  # colcon's setup scripts read unset variables: relax `set -u` while they run.
  case $- in *u*) _wctls_nounset=1; set +u ;; *) _wctls_nounset= ;; esac
  # shellcheck disable=SC1091
  source "$_wctls_root/install/setup.bash"
  [ -n "$_wctls_nounset" ] && set -u
  unset _wctls_nounset
  # The installed executables by their bare names (process_bag, calibrate, score, ...), as
  # `ros2 run wctls_ros <name>` would find them.
  case ":$PATH:" in
    *":$_wctls_root/install/wctls_ros/lib/wctls_ros:"*) ;;
    *) export PATH="$_wctls_root/install/wctls_ros/lib/wctls_ros:$PATH" ;;
  esac
fi
unset _wctls_root
