#!/usr/bin/env bash
# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0
#
# pip install into a venv (created if missing), with one progress line instead of minutes of
# silence: the first install fetches about 250 MB of ROS 2 Jazzy wheels.
# Usage: tools/pip_install.sh VENV PIP_ARGUMENTS...
set -euo pipefail
venv=${1:?usage: pip_install.sh VENV PIP_ARGUMENTS...}
shift
[ -x "$venv/bin/python" ] || "${PYTHON:-python3}" -m venv "$venv"
echo "pip: installing into $venv"
# On a terminal the count updates in place; in a log it is a line per 25 packages.
[ -t 1 ] && every=1 || every=25
"$venv/bin/python" -m pip install --disable-pip-version-check --progress-bar off "$@" 2>&1 \
  | awk -v every="$every" '
      /^Collecting / { n++; if (n % every == 0) { printf every == 1 ? "\r" : "";
                         printf "  %d packages resolved%s", n, every == 1 ? "" : "\n"; fflush() } }
      /^Installing collected packages/ { printf "%s  installing %d packages...\n",
                                          every == 1 ? "\n" : "", n; fflush() }
      /^(ERROR|error|Traceback)/ || failed { failed = 1; print }'
