#!/usr/bin/env bash
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0
#
# Copy the installed executables into a venv's lib/wctls_ros/, run by that venv's Python, as a
# colcon build on a stock ROS install makes them run by /usr/bin/python3. tools/env.sh with
# WCTLS_VENV=<venv> finds them first (AMENT_PREFIX_PATH, PATH).
# Usage: tools/stock_executables.sh VENV
set -euo pipefail
venv=$(cd "${1:?usage: stock_executables.sh VENV}" && pwd)
root=$(cd "$(dirname "$0")/.." && pwd)
mkdir -p "$venv/lib/wctls_ros"
for executable in "$root"/install/wctls_ros/lib/wctls_ros/*; do
  copy="$venv/lib/wctls_ros/$(basename "$executable")"
  sed "1s|^#!.*|#!$venv/bin/python|" "$executable" > "$copy"
  chmod +x "$copy"
done
