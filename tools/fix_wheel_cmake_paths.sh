#!/usr/bin/env bash
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0
#
# The ROS 2 wheels' CMake export files name include directories of the machine that built them
# (/opt/python/cp311-cp311/...). CMake refuses imported targets with non-existent paths, so point
# them at this venv's Python and numpy headers. Idempotent; touches files inside the venv only.
set -euo pipefail
venv=${1:?usage: fix_wheel_cmake_paths.sh VENV}
py="$venv/bin/python"
py_include=$("$py" -c "import sysconfig; print(sysconfig.get_paths()['include'])")
np_include=$("$py" -c "import numpy; print(numpy.get_include())")
built_py_include=/opt/python/cp311-cp311/include/python3.11
built_np_include=/opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include
files=$(grep -rlF -e "$built_py_include" -e "$built_np_include" "$venv/share" || true)
for f in $files; do
  sed -i -e "s#$built_np_include#$np_include#g" -e "s#$built_py_include#$py_include#g" "$f"
done
echo "fixed CMake paths in $(echo "$files" | grep -c . || true) files"
