"""
Scan simulation over 2D floor plans (numpy only, no ROS).

Floor plans are YAML files (two bundled: ``environment_a`` and ``environment_b``, shaped like the
paper's rooms); :func:`simulate_ranges` turns a plan seen from a sensor pose into noisy ranges
under a documented :class:`NoiseModel`.
"""

from .floorplan import BUNDLED_PLANS, floor_plan_from_dict, FloorPlan, load_floor_plan
from .raycast import cast_rays
from .scanner import (full_turn_bearings, NOISELESS, NoiseModel, S1_BEAMS_PER_TURN,
                      S1_BEARING_SIGMA_RAD, S1_RANGE_SIGMA_M, simulate_ranges)

__all__ = [
    'BUNDLED_PLANS', 'FloorPlan', 'NOISELESS', 'NoiseModel', 'S1_BEAMS_PER_TURN',
    'S1_BEARING_SIGMA_RAD', 'S1_RANGE_SIGMA_M', 'cast_rays', 'floor_plan_from_dict',
    'full_turn_bearings', 'load_floor_plan', 'simulate_ranges',
]
