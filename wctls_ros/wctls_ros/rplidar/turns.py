# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Turn assembly: decoded samples in, complete 360-degree turns with honest timing out (pure).

A new turn starts where the raw angle falls back: at a flagged start sample whose angle is below
its predecessor's (a corrupted S bit alone does not split a turn), or wherever the angle drops by
more than 270 degrees (a lost start sample does not merge two turns). Once a turn has given the
angle per sample, the sample slots between consecutive samples (counted from stream offsets, so
untouched by timing jitter) also count the wraps between them: a gap in the stream longer than a
turn (a damaged link) cannot merge two turns either. The first, partial turn after a (re)start
is dropped.

Timing uses the device's own sample clock: with ``us`` the mode's microseconds per sample and
``step`` the median angle between consecutive samples, the rotation period is
``360 / step * us``. Each sample's measurement time is bounded above by its frame's receive time
minus the link's transmission time and the samples measured after it in that frame; the turn's
first-sample time is the tightest of these bounds carried back along the turn at the measured
rotation rate, so reader-thread delays do not leak into the stamp.
"""

from dataclasses import dataclass

import numpy as np

from .protocol import Samples

_MISSED_START_DROP_DEG = 270.0


@dataclass(frozen=True)
class Turn:
    """
    One rotation's samples in measurement order, with timing.

    :ivar angle_deg: raw angles, degrees clockwise, in [0, 360)
    :ivar distance_mm: distances, mm, 0 = no return
    :ivar quality: 6-bit qualities
    :ivar first_sample_s: estimated measurement time of the first sample, monotonic clock, s
    :ivar period_s: rotation period from the device's sample clock, s
    :ivar last_byte_s: receive time of the frame carrying the last sample, monotonic clock, s
    """

    angle_deg: np.ndarray
    distance_mm: np.ndarray
    quality: np.ndarray
    first_sample_s: float
    period_s: float
    last_byte_s: float


class TurnAssembler:
    """
    Split a sample stream into complete turns.

    :param us_per_sample: the scan mode's sample period, microseconds
    :param frame_transmission_s: time one frame takes on the link (serial: bytes * 10 / baud)
    :param max_samples: a turn growing past this is dropped (no turn boundary in sight)
    """

    def __init__(self, us_per_sample: float, frame_transmission_s: float,
                 max_samples: int = 8192):
        self._sample_s = us_per_sample * 1e-6
        self._transmission_s = frame_transmission_s
        self._max_samples = max_samples
        self._parts = []
        self._size = 0
        self._complete = False
        self._last_angle = None
        self._last_slot = None
        self._step_deg = None
        self._turn_end_s = None
        self.dropped_turns = 0

    def turn_end_eta_s(self):
        """
        Predict when the turn being assembled ends: a period after the last complete one.

        :return: monotonic time, s; None until a turn has been completed
        """
        return self._turn_end_s

    def push(self, samples: Samples, received_s: np.ndarray) -> list:
        """
        Add decoded samples; return the turns they complete.

        :param samples: decoded samples in stream order
        :param received_s: receive time of each sample's frame, monotonic clock, s
        :return: list of :class:`Turn`
        """
        if not len(samples):
            return []
        angle = samples.angle_deg
        measured_s = (received_s - self._transmission_s
                      - samples.samples_after * self._sample_s)
        first = self._last_angle is None
        previous = np.concatenate([[angle[0] if first else self._last_angle], angle[:-1]])
        drop = previous - angle
        boundary = (samples.start & (drop > 0.0)) | (drop > _MISSED_START_DROP_DEG)
        if self._step_deg is not None and not first:
            swept_deg = np.diff(samples.slot, prepend=self._last_slot) * self._step_deg
            # Wraps between consecutive samples by their slots; a fall in angle already shows
            # one (and is judged above), so only wraps the angles cannot show count here.
            wraps = np.floor((swept_deg + drop) / 360.0 + 0.5)
            boundary |= wraps >= 1.0 + (drop > 0.0)
        self._last_angle = angle[-1]
        self._last_slot = samples.slot[-1]
        columns = (angle, samples.distance_mm, samples.quality, measured_s, received_s)
        turns = []
        begin = 0
        for cut in np.flatnonzero(boundary):
            self._append(columns, begin, cut)
            turn = self._close()
            if turn is not None:
                turns.append(turn)
            begin = cut
        self._append(columns, begin, len(angle))
        return turns

    def _append(self, columns: tuple, begin: int, end: int):
        """Add ``columns[begin:end]`` to the turn being assembled."""
        if end <= begin:
            return
        self._parts.append(tuple(c[begin:end] for c in columns))
        self._size += end - begin
        if self._size > self._max_samples:
            self.dropped_turns += 1
            self._parts, self._size, self._complete = [], 0, False

    def _close(self):
        """End the turn being assembled; return it if it was complete and usable."""
        parts, complete = self._parts, self._complete
        self._parts, self._size, self._complete = [], 0, True
        if not complete or not parts:
            return None
        angle, distance, quality, measured_s, received_s = (
            np.concatenate(c) for c in zip(*parts))
        steps = np.diff(angle)
        steps = steps[steps > 0.0]
        if not steps.size:
            self.dropped_turns += 1
            return None
        self._step_deg = step_deg = float(np.median(steps))
        period_s = 360.0 / step_deg * self._sample_s
        first_sample_s = float(np.min(measured_s - (angle - angle[0]) / step_deg * self._sample_s))
        self._turn_end_s = first_sample_s + (2.0 - angle[0] / 360.0) * period_s
        return Turn(angle_deg=angle, distance_mm=distance, quality=quality,
                    first_sample_s=first_sample_s, period_s=period_s,
                    last_byte_s=float(received_s[-1]))
