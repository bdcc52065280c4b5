# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
An emulated RPLIDAR of every model; the ``rplidar_emulator`` executable (:mod:`.cli`) runs it.

``device`` is the RPLIDAR itself (pure: requests in, answers and the timed scan stream out, from
any scene that gives a distance per raw angle), ``server`` serves devices on a pseudo-terminal
and TCP and takes control commands, ``room`` is the built-in scene (a furnished room, ray cast by
``raycast``). Another scene can be injected (:func:`.cli.main`), as the lab's floor plans are.
"""
