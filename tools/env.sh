# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0
#
# Source this from the repository root after `make build` to use the workspace in a shell:
#   source tools/env.sh
# It activates the venv holding the ROS 2 Jazzy wheels and overlays the colcon install space,
# like `source /opt/ros/jazzy/setup.bash && source install/setup.bash` on a full ROS install.
# WCTLS_VENV names another venv of the checkout (`make test` uses .venv-stock, a stock install's
# libraries, whose copies of the installed executables run its own Python).
_wctls_root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
_wctls_venv="$_wctls_root/${WCTLS_VENV:-.venv}"
# shellcheck disable=SC1091
source "$_wctls_venv/bin/activate"
export AMENT_PREFIX_PATH="$_wctls_venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
export CMAKE_PREFIX_PATH="$_wctls_venv${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
if [ -f "$_wctls_root/install/local_setup.bash" ]; then
  # colcon's setup scripts read unset variables: relax `set -u` while they run.
  case $- in *u*) _wctls_nounset=1; set +u ;; *) _wctls_nounset= ;; esac
  # The install space alone: its underlay is the venv, set up above.
  # shellcheck disable=SC1091
  source "$_wctls_root/install/local_setup.bash"
  [ -n "$_wctls_nounset" ] && set -u
  unset _wctls_nounset
  # The installed executables by their bare names (process_bag, calibrate, score, ...), as
  # `ros2 run <package> <name>` would find them (the venv's own copies first, if it has any).
  for _wctls_bin in "$_wctls_root"/install/wctls_*/lib/wctls_* "$_wctls_venv"/lib/wctls_*; do
    case ":$PATH:" in
      *":$_wctls_bin:"*) ;;
      *) [ -d "$_wctls_bin" ] && export PATH="$_wctls_bin:$PATH" ;;
    esac
  done
  unset _wctls_bin
fi
unset _wctls_root _wctls_venv
