# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The named data the steps of the pipeline pass each other: typed named tuples, not numbered ones.

numba compiles a ``typing.NamedTuple`` into a struct whose fields are read by name, as
arguments and as results, also from its on-disk cache: a range sigma cannot take a bearing
sigma's place, nothing is indexed by number, and a field added to a record reaches every kernel
that reads the record without a change to the calls in between. A record of arrays holds
references to them (no copy). The compiled core (:mod:`.numba_core`) passes them between its
kernels; the numpy core's end trims (:mod:`.numpy_core.segmentation`), corner candidates and
corner end rule (:mod:`.numpy_core.corners`) take the same records, the rule's fields arrays over
all candidate corners at once where the compiled one has a number per corner. The compiled
core's segments and corners are the field tables of :class:`~.features.SegmentSet` and
:class:`~.features.CornerSet` as named tuples (numba compiles no dataclass): the same fields in
the same order. Plain Python classes: importing this module imports no numba.
"""

import collections
from typing import Any, Generic, NamedTuple, TypeVar

from .features import CornerSet, FlagArray, FloatArray, IndexArray, SegmentSet

# A number of one corner in the compiled core, which takes the corners one at a time, and an
# array of it over every corner in the numpy core's corner end rule: float or FloatArray, int
# or IndexArray.
PerCorner = TypeVar('PerCorner')


def _arrays_of(name: str, table: Any) -> Any:
    """
    Return a named tuple of the fields of a field table, in their order.

    A type checker cannot read the fields of a named tuple made from a table; nothing typed
    reads these (the compiled kernels are not).
    """
    return collections.namedtuple(name, table.__dataclass_fields__, module=__name__)


SegmentArrays = _arrays_of('SegmentArrays', SegmentSet)
CornerArrays = _arrays_of('CornerArrays', CornerSet)


class Settings(NamedTuple):
    """The FeatureConfig fields the compiled pipeline reads, as plain int, float or bool."""

    method_code: int
    range_sigma_m: float
    bearing_sigma_rad: float
    range_sigma_from_scan: bool
    common_range_sigma_m: float
    breakpoint_lambda_rad: float
    iepf_threshold_m: float
    iepf_noise_sigmas: float
    merge_chi2: float
    merge_max_missing_beams: int
    end_offset_sigmas: float
    residual_scaling: bool
    model_error_sigma_m: float
    wall_flatness_sigma_m: float
    min_segment_points: int
    min_segment_length_m: float
    min_corner_angle_rad: float
    min_wall_beam_angle_rad: float
    corner_end_sigmas: float
    corner_end_floor_m: float
    max_range_sigma_m: float


class Noise(NamedTuple):
    """
    The noise one scan is processed with (docs/derivation.md#decision-noise).

    :ivar range_sigma_m: the range noise the fits weigh the returns by, m
    :ivar bearing_sigma_rad: the bearing noise, rad
    :ivar deciding_sigma_m: the range noise and the model error in quadrature, m: what every
        decision (breakpoints, splits, merges, trims, corners) tolerates
    """

    range_sigma_m: float
    bearing_sigma_rad: float
    deciding_sigma_m: float


class Returns(NamedTuple):
    """
    A scan's valid returns, in beam order or (the pipeline's contour) in circular order.

    :ivar beam_index: each return's beam index, shape (n,)
    :ivar range_m: its range, shape (n,), m
    :ivar bearing_rad: its bearing, shape (n,), rad
    :ivar x_m: its x, shape (n,), m
    :ivar y_m: its y, shape (n,), m
    """

    beam_index: IndexArray
    range_m: FloatArray
    bearing_rad: FloatArray
    x_m: FloatArray
    y_m: FloatArray


class BeamGrid(NamedTuple):
    """
    The beams of a scan, valid or not.

    :ivar beam_count: how many
    :ivar step_rad: |angle_increment|, the bearing step between neighbours, rad
    :ivar full_turn: whether they cover a full turn (the first and last are neighbours)
    """

    beam_count: int
    step_rad: float
    full_turn: bool


class Segments(NamedTuple):
    """
    Half-open runs [start, stop) of positions in the circular order (modulo its length).

    :ivar start: first position of each, shape (S,)
    :ivar stop: one past its last position, shape (S,)
    :ivar chain: the chain (run between breakpoints) it lies on, shape (S,)
    """

    start: IndexArray
    stop: IndexArray
    chain: IndexArray


class Lines(NamedTuple):
    """
    One line x cos(angle) + y sin(angle) = radius per segment.

    :ivar angle_rad: normal angle, shape (S,), rad
    :ivar radius_m: radius, shape (S,), m
    """

    angle_rad: FloatArray
    radius_m: FloatArray


class CornerCandidates(NamedTuple):
    """
    Intersections of neighbouring walls that are not close to parallel.

    :ivar xy_m: position, shape (C, 2), m
    :ivar yaw_rad: bisector of the walls, towards the open side the sensor sees, shape (C,), rad
    :ivar covariance: covariance of (x, y, yaw), shape (C, 3, 3)
    :ivar opening_angle_rad: angle between the walls through the open side, shape (C,), rad
    :ivar first_wall: the earlier wall of each, shape (C,)
    :ivar second_wall: the later wall, shape (C,)
    """

    xy_m: FloatArray
    yaw_rad: FloatArray
    covariance: FloatArray
    opening_angle_rad: FloatArray
    first_wall: IndexArray
    second_wall: IndexArray


class CornerEndRule(NamedTuple):
    """
    The tolerances of the corner end rule (docs/derivation.md#corners, "Corner end rule").

    :ivar sigmas: tolerance in standard deviations
    :ivar floor_m: tolerance floor, m
    :ivar window: most returns between the two walls (more: not adjacent)
    :ivar run_sigmas: largest sum of normalised residuals over sqrt(count) of a run of returns
        in front of a wall (claimed beyond its segment) or behind it (seen through it); 0: no
        such test
    """

    sigmas: float
    floor_m: float
    window: int
    run_sigmas: float


class EndWindow(NamedTuple, Generic[PerCorner]):
    """
    The returns the corner end rule looks at between two walls, in the circular order.

    Column 0 is the first wall's facing end (its last return), the last column the second
    wall's (its first return); between them the returns that belong to neither segment, as
    many as there are up to the rule's window.

    :ivar x_m: x of each column's return, shape (W,), m
    :ivar y_m: y of each column's return, shape (W,), m
    :ivar sigma_m: its position noise, sqrt(range_sigma^2 + (r bearing_sigma)^2), shape (W,), m
    :ivar line_tolerance_m: how far off a line it still lies on it, shape (W,), m
    :ivar in_window: whether the column holds a facing end or a return between them, (W,)
    :ivar between: how many returns lie between the two walls (also beyond the window; the
        numpy core: per corner)
    """

    x_m: FloatArray
    y_m: FloatArray
    sigma_m: FloatArray
    line_tolerance_m: FloatArray
    in_window: FlagArray
    between: PerCorner


class WallAtCorner(NamedTuple, Generic[PerCorner]):
    """
    One wall of a corner, seen from the corner.

    :ivar normal_x: x of the unit normal of its line
    :ivar normal_y: y of that normal
    :ivar radius_m: its line's radius, m
    :ivar inward_x: x of the unit direction from the corner into the wall (towards its middle)
    :ivar inward_y: y of that direction
    :ivar along_sigma_m: the corner's standard deviation along the wall, m
    :ivar spacing_m: the spacing of the beams on the wall at the corner, m
    :ivar tolerance_m: how far from the corner a return along the wall still reaches it, m
    """

    normal_x: PerCorner
    normal_y: PerCorner
    radius_m: PerCorner
    inward_x: PerCorner
    inward_y: PerCorner
    along_sigma_m: PerCorner
    spacing_m: PerCorner
    tolerance_m: PerCorner


class AlongWall(NamedTuple):
    """
    Where the returns of an end window lie with respect to one wall of the corner.

    :ivar in_front_m: how far each lies in front of the wall's line (towards the sensor), m
    :ivar along_m: how far from the corner into the wall, m (negative: past the corner)
    :ivar on_line: whether it lies on the wall's line (within its line tolerance), (W,)
    """

    in_front_m: FloatArray
    along_m: FloatArray
    on_line: FlagArray


class TrackRules(NamedTuple):
    """
    The landmark tracker's rules as its compiled kernels read them (one record per tracker).

    The fields of :class:`wctls_ros.frontend.tracking.TrackerConfig` of the same names, and:

    :ivar white_share: the share of an observation's covariance that is new in every scan,
        1 - ``persistent_share``
    """

    white_share: float
    confirm_hits: int
    drop_tentative_misses: int
    lose_misses: int
    memory_scans: int
    max_hypotheses: int
    occlusion_margin_m: float
