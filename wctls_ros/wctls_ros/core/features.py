# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
The extracted features of one scan.

Segments and corners are held as arrays (``SegmentSet``, ``CornerSet``: one row per feature, fast
to convert to messages) and read one at a time as small records (``Segment``, ``Corner``):
``features.corners[0].x_m`` or ``for corner in features.corners``.
"""

from dataclasses import dataclass, fields, MISSING
import math
from typing import (Annotated, Any, ClassVar, Dict, get_args, get_type_hints, List, Tuple, Type,
                    TypeVar)

import numpy as np
from numpy.typing import NDArray

# The array types of the field tables, and the dtype of each.
FloatArray = NDArray[np.float64]
IndexArray = NDArray[np.intp]
FlagArray = NDArray[np.bool_]
_DTYPES = {FloatArray: np.dtype(np.float64), IndexArray: np.dtype(np.intp),
           FlagArray: np.dtype(np.bool_)}


@dataclass(frozen=True)
class Segment:
    """
    One straight segment: the line x cos(angle) + y sin(angle) = radius and its extent.

    A row of a :class:`SegmentSet`, whose field table says what each field is, in what unit:
    a number, or an array of the row's shape there.
    """

    angle_rad: float
    radius_m: float
    covariance: FloatArray
    line: FloatArray
    line_covariance: FloatArray
    line_offset_jacobian: FloatArray
    start_xy_m: FloatArray
    end_xy_m: FloatArray
    first_index: int
    last_index: int
    num_points: int
    residual_chi2_dof: float


@dataclass(frozen=True)
class Corner:
    """
    One corner: where two adjacent walls meet.

    :ivar x_m: position x, m
    :ivar y_m: position y, m
    :ivar yaw_rad: bisector of the walls, pointing into the open side the sensor sees, rad
    :ivar covariance: joint covariance of (x, y, yaw), shape (3, 3): m^2, m rad, rad^2
    :ivar opening_angle_rad: angle between the walls through the open side, rad in (0, 2 pi)
    :ivar first_segment: index of the earlier segment in the same Features
    :ivar second_segment: index of the later segment
    :ivar first_end_seen: a return of the first wall lies within a beam of the corner (else the
        corner sits in a run of beams without returns, e.g. a dark corner)
    :ivar second_end_seen: the same for the second wall
    """

    x_m: float
    y_m: float
    yaw_rad: float
    covariance: FloatArray
    opening_angle_rad: float
    first_segment: int
    second_segment: int
    first_end_seen: bool
    second_end_seen: bool

    @property
    def position_covariance(self) -> np.ndarray:
        """
        Return the covariance of (x, y).

        :return: shape (2, 2), m^2
        """
        return self.covariance[:2, :2]


_COLUMNS: Dict[type, Dict[str, Tuple[np.dtype, Tuple[int, ...]]]] = {}


def _columns(table: Type['_Columns']) -> Dict[str, Tuple[np.dtype, Tuple[int, ...]]]:
    """Return each field's dtype and the shape of one row, as the field table declares them."""
    if table not in _COLUMNS:
        declared, columns = get_type_hints(table, include_extras=True), {}
        for name in table.__dataclass_fields__:
            array, row_shape = get_args(declared[name])
            columns[name] = _DTYPES[array], row_shape
        _COLUMNS[table] = columns
    return _COLUMNS[table]


Table = TypeVar('Table', bound='_Columns')


class _Columns:
    """
    A field table: arrays with one row per feature, the fields of a frozen dataclass.

    Each field is declared with its array type (``FloatArray``, ``IndexArray``, ``FlagArray``)
    and the shape of one feature's row: ``Annotated[FloatArray, ()]`` is a number per feature,
    shape (n,), ``Annotated[FloatArray, (2, 2)]`` shape (n, 2, 2). From these declarations come
    the sets with no or some features (:meth:`empty`, :meth:`filled`), the selection of rows
    (:meth:`select`), the check of a set's arrays (:meth:`problems`) and the compiled core's
    record of the same fields (:mod:`.records`).
    """

    __dataclass_fields__: ClassVar[Dict[str, Any]]
    # Whether every float of every row is finite (the pipelines drop a feature that is not).
    all_finite: ClassVar[bool] = False

    def __len__(self) -> int:
        return len(getattr(self, next(iter(self.__dataclass_fields__))))

    def select(self: Table, keep: np.ndarray) -> Table:
        """
        Return the rows where ``keep`` selects (a boolean or index array).

        :param keep: selection over the rows
        :return: the selected rows
        """
        return type(self)(*(getattr(self, name)[keep] for name in self.__dataclass_fields__))

    @classmethod
    def filled(cls: Type[Table], count: int, **given: np.ndarray) -> Table:
        """
        Return ``count`` rows with the given fields, the others NaN (0 or False, not floats).

        :param count: how many rows
        :param given: fields by name, each with ``count`` rows
        :return: the rows
        """
        blank = {name: np.full((count,) + row_shape, np.nan if dtype.kind == 'f' else 0, dtype)
                 for name, (dtype, row_shape) in _columns(cls).items()}
        return cls(**{**blank, **given})

    @classmethod
    def of_fields(cls: Type[Table], arrays: Tuple[np.ndarray, ...]) -> Table:
        """
        Return the set of the arrays of every field, in the field table's order, unchecked.

        For the compiled core, whose records hold the fields in this order with the declared
        dtypes and shapes (its tests check them with :meth:`problems`): the frozen dataclass's
        ``__init__`` sets each field through ``object.__setattr__``, about a microsecond per
        scan for a segment and a corner set, where this fills the instance's dict at once.

        :param arrays: one array per field, in the order of the field table
        :return: the set
        """
        table = object.__new__(cls)
        table.__dict__.update(zip(cls.__dataclass_fields__, arrays))
        return table

    @classmethod
    def empty(cls: Type[Table]) -> Table:
        """
        Return a set without rows.

        :return: the empty set
        """
        return cls.filled(0)

    def problems(self) -> List[str]:
        """
        Return where the arrays disagree with the field table, one line each (none: they agree).

        A field must have the declared dtype and as many rows as the first field, each of the
        declared shape; with ``all_finite``, every float must be finite.

        :return: the disagreements
        """
        found, count = [], len(self)
        for name, (dtype, row_shape) in _columns(type(self)).items():
            value = getattr(self, name)
            if value.dtype != dtype or value.shape != (count,) + row_shape:
                found.append(f'{name}: {value.dtype} {value.shape}, not {dtype} '
                             f'{(count,) + row_shape}')
            elif self.all_finite and dtype.kind == 'f' and not np.isfinite(value).all():
                found.append(f'{name}: not finite')
        return found


class _Rows(_Columns):
    """A field table read one row (record) at a time."""

    def __iter__(self):
        return (self[i] for i in range(len(self)))


def _number(entry):
    """Return a row's entry of a field, a Python number where it is one number."""
    return entry.item() if entry.ndim == 0 else entry


@dataclass(frozen=True)
class SegmentSet(_Rows):
    """
    The segments of one scan as arrays, one row per segment (a :class:`Segment`).

    :ivar angle_rad: normal angle, from the sensor towards the line, rad in (-pi, pi]
    :ivar radius_m: distance of the line from the sensor, m (>= 0)
    :ivar covariance: covariance of (angle, radius): rad^2, rad m, m^2 (all noise terms of the
        configuration, the common-mode range offset included)
    :ivar line: (a, b, c) of a x + b y + c = 0 as the method defines them
    :ivar line_covariance: covariance of (a, b, c) from the independent per-return noise
    :ivar line_offset_jacobian: d(a, b, c) / d(range offset common to every return of the
        scan), per m (the common-mode part of the covariance is sigma^2 g g^T)
    :ivar start_xy_m: first return projected on the line, m
    :ivar end_xy_m: last return projected on the line, m
    :ivar first_index: beam index of the first return in the scan's ranges
    :ivar last_index: beam index of the last return (smaller than first_index on a segment
        that crosses the seam of a full turn)
    :ivar num_points: number of returns fitted
    :ivar residual_chi2_dof: sum of the squared residuals from the line, each over the
        variance of the return across the line, per degree of freedom (num_points - 2): about 1
        when the wall is straight and the noise model right, above it when the wall bows or the
        noise is larger than modelled
    """

    all_finite = True

    angle_rad: Annotated[FloatArray, ()]
    radius_m: Annotated[FloatArray, ()]
    covariance: Annotated[FloatArray, (2, 2)]
    line: Annotated[FloatArray, (3,)]
    line_covariance: Annotated[FloatArray, (3, 3)]
    line_offset_jacobian: Annotated[FloatArray, (3,)]
    start_xy_m: Annotated[FloatArray, (2,)]
    end_xy_m: Annotated[FloatArray, (2,)]
    first_index: Annotated[IndexArray, ()]
    last_index: Annotated[IndexArray, ()]
    num_points: Annotated[IndexArray, ()]
    residual_chi2_dof: Annotated[FloatArray, ()]

    def __getitem__(self, i: int) -> Segment:
        return Segment(*(_number(getattr(self, name)[i]) for name in self.__dataclass_fields__))


@dataclass(frozen=True)
class CornerSet(_Rows):
    """
    The corners of one scan as arrays, one row per corner (fields as in :class:`Corner`).

    The field table of corners: xy_m is (x_m, y_m) and end_seen (first_end_seen,
    second_end_seen) of a :class:`Corner`; covariance is over (x, y, yaw).
    """

    all_finite = True

    xy_m: Annotated[FloatArray, (2,)]
    yaw_rad: Annotated[FloatArray, ()]
    covariance: Annotated[FloatArray, (3, 3)]
    opening_angle_rad: Annotated[FloatArray, ()]
    first_segment: Annotated[IndexArray, ()]
    second_segment: Annotated[IndexArray, ()]
    end_seen: Annotated[FlagArray, (2,)]

    def __getitem__(self, i: int) -> Corner:
        return Corner(float(self.xy_m[i, 0]), float(self.xy_m[i, 1]), float(self.yaw_rad[i]),
                      self.covariance[i], float(self.opening_angle_rad[i]),
                      int(self.first_segment[i]), int(self.second_segment[i]),
                      bool(self.end_seen[i, 0]), bool(self.end_seen[i, 1]))


@dataclass(frozen=True)
class Features:
    """
    Everything extracted from one scan.

    :ivar method: the line fit used: 'utls', 'wtls', 'wctls' or 'ml'
    :ivar segments: the segments, in scan order
    :ivar corners: the corners, in scan order; their segment indices point into ``segments``
    :ivar work_limited: the per-scan work bound stopped splitting or merging early: returns
        that were still not straight after the allowed passes are left out, or neighbouring
        segments stayed apart (a scan no real scene gives; see
        :func:`wctls_ros.core.numpy_core.segmentation.pass_budget`)
    :ivar range_sigma_m: the range noise the scan was processed with (its own estimate when
        ``range_sigma_from_scan``, never below ``range_sigma_m``), m; NaN for a scan with too
        few returns to process
    :ivar noise_implausible: the scan's range-noise estimate exceeded ``max_range_sigma_m``:
        no features (:mod:`wctls_ros.core.plausibility`)
    :ivar implausible_features: segments and corners left out because their position std
        exceeded the plausibility bound for their range
    """

    method: str
    segments: SegmentSet
    corners: CornerSet
    work_limited: bool = False
    range_sigma_m: float = math.nan
    noise_implausible: bool = False
    implausible_features: int = 0

    @classmethod
    def of_scan(cls, method: str, segments: SegmentSet, corners: CornerSet, work_limited: bool,
                range_sigma_m: float) -> 'Features':
        """
        Return the features of a scan that passed the noise bound, every feature plausible.

        The compiled core's way to them, past the frozen dataclass's ``__init__`` and its
        ``object.__setattr__`` per field (see :meth:`SegmentSet.of_fields`); the other fields
        keep their defaults.
        """
        features = object.__new__(cls)
        values = features.__dict__
        values.update(_FEATURES_DEFAULTS)
        # One by one: keywords to update() would build a dict of them first (0.15 us more).
        values['method'], values['segments'], values['corners'] = method, segments, corners
        values['work_limited'], values['range_sigma_m'] = work_limited, range_sigma_m
        return features


# The fields of Features that have defaults, and those defaults.
_FEATURES_DEFAULTS = {field.name: field.default for field in fields(Features)
                      if field.default is not MISSING}


@dataclass(frozen=True)
class SegmentReturns:
    """
    The returns of S segments laid end to end.

    :ivar rho: ranges, shape (P,), m
    :ivar theta: bearings, shape (P,), rad
    :ivar x: rho cos(theta), shape (P,), m
    :ivar y: rho sin(theta), shape (P,), m
    :ivar offsets: first return of each segment, shape (S,)
    :ivar counts: returns per segment, shape (S,), each >= 2
    """

    rho: np.ndarray
    theta: np.ndarray
    x: np.ndarray
    y: np.ndarray
    offsets: np.ndarray
    counts: np.ndarray


def segment_returns(rho, theta, offsets, counts, x=None, y=None) -> SegmentReturns:
    """
    Bundle the returns of consecutive segments for the batched fits.

    :param rho: ranges, shape (P,), m
    :param theta: bearings, shape (P,), rad
    :param offsets: first return of each segment, shape (S,)
    :param counts: returns per segment, shape (S,), each >= 2
    :param x: rho cos(theta) when already known, shape (P,), m
    :param y: rho sin(theta) when already known, shape (P,), m
    :return: the bundle
    """
    rho = np.asarray(rho, dtype=float)
    theta = np.asarray(theta, dtype=float)
    counts = np.asarray(counts, dtype=np.intp)
    if x is None or y is None:
        x, y = rho * np.cos(theta), rho * np.sin(theta)
    return SegmentReturns(rho, theta, x, y, np.asarray(offsets, dtype=np.intp), counts)


@dataclass(frozen=True)
class LineFits(_Columns):
    """
    Fitted lines of S segments, in the method's own form and in normal form.

    :ivar line: (a, b, c) of a x + b y + c = 0 as the method defines them, shape (S, 3)
    :ivar line_covariance: covariance of (a, b, c), shape (S, 3, 3), in units of (a, b, c)^2
    :ivar angle_rad: direction of the line's normal, pointing from the origin to the line,
        shape (S,), rad in (-pi, pi]
    :ivar radius_m: distance of the line from the origin, shape (S,), m, >= 0
    :ivar normal_covariance: covariance of (angle, radius), shape (S, 2, 2): rad^2, rad m, m^2
    :ivar line_offset_jacobian: d(a, b, c) / d(range offset common to all returns), (S, 3), per m
    :ivar normal_offset_jacobian: d(angle, radius) / d(common range offset), (S, 2): rad/m, m/m
    """

    line: Annotated[FloatArray, (3,)]
    line_covariance: Annotated[FloatArray, (3, 3)]
    angle_rad: Annotated[FloatArray, ()]
    radius_m: Annotated[FloatArray, ()]
    normal_covariance: Annotated[FloatArray, (2, 2)]
    line_offset_jacobian: Annotated[FloatArray, (3,)]
    normal_offset_jacobian: Annotated[FloatArray, (2,)]
