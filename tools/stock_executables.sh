#!/usr/bin/env bash
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0
#
# Copy the installed executables into a venv's lib/<package>/, run by that venv's Python, as a
# colcon build on a stock ROS install makes them run by /usr/bin/python3. tools/env.sh with
# WCTLS_VENV=<venv> finds them first (AMENT_PREFIX_PATH, PATH).
# Usage: tools/stock_executables.sh VENV
set -euo pipefail
venv=$(cd "${1:?usage: stock_executables.sh VENV}" && pwd)
root=$(cd "$(dirname "$0")/.." && pwd)
for package in wctls_ros wctls_rplidar wctls_lab; do
  mkdir -p "$venv/lib/$package"
  for executable in "$root/install/$package/lib/$package"/*; do
    copy="$venv/lib/$package/$(basename "$executable")"
    sed "1s|^#!.*|#!$venv/bin/python|" "$executable" > "$copy"
    chmod +x "$copy"
  done
done
