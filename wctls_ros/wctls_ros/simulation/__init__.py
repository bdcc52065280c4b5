# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Scan simulation over 2D floor plans (numpy only, no ROS).

Floor plans are YAML files (two bundled: ``environment_a`` and ``environment_b``, shaped like the
paper's rooms); :func:`simulate_ranges` turns a plan seen from a sensor pose into noisy ranges
under a documented :class:`NoiseModel`; :func:`simulate_recording` makes repeated scans of a
still (or moving) sensor and :func:`visible_corners` tells which true corners it can see.
"""

from .floorplan import BUNDLED_PLANS, floor_plan_from_dict, FloorPlan, load_floor_plan
from .raycast import cast_rays
from .recording import Recording, SCAN_PERIOD_S, simulate_recording
from .scanner import (full_turn_bearings, NOISELESS, NoiseModel, S1_BEAMS_PER_TURN,
                      S1_BEARING_SIGMA_RAD, S1_RANGE_SIGMA_M, simulate_ranges)
from .visibility import visible_corners

__all__ = [
    'BUNDLED_PLANS', 'FloorPlan', 'NOISELESS', 'NoiseModel', 'Recording', 'S1_BEAMS_PER_TURN',
    'S1_BEARING_SIGMA_RAD', 'S1_RANGE_SIGMA_M', 'SCAN_PERIOD_S', 'cast_rays',
    'floor_plan_from_dict', 'full_turn_bearings', 'load_floor_plan', 'simulate_ranges',
    'simulate_recording', 'visible_corners',
]
