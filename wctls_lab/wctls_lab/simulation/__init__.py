# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Scan simulation over 2D floor plans (numpy only, no ROS).

Floor plans are YAML files (bundled: ``environment_a`` and ``environment_b``, shaped like the
paper's rooms, and their lived-in variants ``environment_a_cluttered`` and
``environment_b_cluttered`` with clutter, a walking person, glass and bowed or rough walls);
:func:`simulate_scan` turns what a sensor sees (:class:`Scene`) into ranges under a documented
:class:`NoiseModel` (noise, mixed pixels, dropouts, bearing quantisation; presets in
:data:`SENSOR_MODELS`); :func:`simulate_recording` makes repeated scans of a still (or moving)
sensor with the true corners of every scan and which of them it can see.
"""

from wctls_rplidar.emulator.raycast import cast_rays, ray_hits, RayHits

from .floorplan import (BUNDLED_PLANS, CORNER_KINDS, floor_plan_from_dict, FloorPlan,
                        load_floor_plan)
from .recording import Recording, SCAN_PERIOD_S, simulate_recording
from .scanner import (FOOTPRINT_RAYS, full_turn_bearings, NO_RETURN_VALUES, NOISELESS,
                      NoiseModel, S1_BEAMS_PER_TURN, S1_BEARING_SIGMA_RAD, S1_RANGE_SIGMA_M,
                      SENSOR_MODELS, simulate_ranges, simulate_scan)
from .scene import Scene, Surfaces, Walker
from .visibility import visible_corners

__all__ = [
    'BUNDLED_PLANS', 'CORNER_KINDS', 'FOOTPRINT_RAYS', 'FloorPlan', 'NOISELESS',
    'NO_RETURN_VALUES', 'NoiseModel', 'RayHits', 'Recording', 'S1_BEAMS_PER_TURN',
    'S1_BEARING_SIGMA_RAD', 'S1_RANGE_SIGMA_M', 'SCAN_PERIOD_S', 'SENSOR_MODELS', 'Scene',
    'Surfaces', 'Walker', 'cast_rays', 'floor_plan_from_dict', 'full_turn_bearings',
    'load_floor_plan', 'ray_hits', 'simulate_ranges', 'simulate_recording', 'simulate_scan',
    'visible_corners',
]
