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

Timing uses the device's own sample clock (:class:`SampleClock`): a turn's first sample is
stamped by its place in the stream, so consecutive turns lie exactly their samples apart and
reader-thread delays, which a loaded machine makes long, do not leak into the stamps. With
``step`` the median angle between consecutive samples, the rotation period is
``360 / step`` sample periods. Formats whose frames carry the device's timestamp (ultra-dense and
HQ capsules) are stamped on that clock instead, read on the monotonic clock the same way
(a :class:`SampleClock` whose slots are the device's microseconds): a sample's device time is its
frame's timestamp (its first sample's) plus its place in the frame, so stamps follow the
device's own timing, whatever its sample rate, and a frame counted wrongly does not shift them.
"""

import collections
from dataclasses import dataclass
import math
from typing import Optional

import numpy as np

from .protocol import Samples

_MISSED_START_DROP_DEG = 270.0
# How far corrected angles scatter about their grid: express corrections reach 8 degrees, the
# ultra capsules' distance-dependent offsets about as far.
_CORRECTION_SPAN_DEG = 16.0
# The range of a 32-bit device clock (ultra-dense capsules' timestamps wrap after 72 minutes).
_DEVICE_TIME_WRAP_US = 1 << 32
# What a published turn must sweep, degrees, and the share of a rotation it may sweep at most.
MIN_SWEEP_DEG = 180.0
MAX_TURN_SHARE = 1.05
# The least time between the starts of published turns, in rotation periods.
MIN_PERIOD_SHARE = 0.9


class SampleClock:
    """
    The device's sample clock, read on the host's monotonic clock.

    The sample in stream slot n is measured (until) ``origin + n * period``. A sample's frame
    arrives after it was measured, by at least the link's transmission time and the samples
    measured after it in the frame, so each receive time bounds the origin from above. The
    origin is the lowest bound of the last ``WINDOW_S``: a few promptly read frames pin it down
    however late the others were read, and it follows a restart of the device's clock after at
    most that long. The period starts at the mode's nominal one and follows the device's own
    rate (its crystal is not the host's) from the lowest bounds ``SPAN_S`` apart.

    :param sample_s: the scan mode's nominal sample period, s
    """

    WINDOW_S = 2.0
    SPAN_S = 10.0
    MAX_RATE_ERROR = 0.02

    def __init__(self, sample_s: float):
        self._nominal_s = sample_s
        self.period_s = sample_s
        # The tightest bound of each batch of samples: (slot, bound, s).
        self._bounds = collections.deque()

    def add(self, slots: np.ndarray, bounds_s: np.ndarray):
        """
        Take the upper bounds of the measurement times of a batch of samples.

        :param slots: the samples' stream slots
        :param bounds_s: their measurement time bounds, monotonic clock, s
        """
        tightest = int(np.argmin(bounds_s - slots * self.period_s))
        self._bounds.append((float(slots[tightest]), float(bounds_s[tightest])))
        while self._bounds[-1][1] - self._bounds[0][1] > self.SPAN_S:
            self._bounds.popleft()
        slots, bounds_s = np.array(self._bounds).T
        if bounds_s[-1] - bounds_s[0] < 0.5 * self.SPAN_S:
            return
        # The lowest bounds of the first and the last second of the span give the device's rate
        # (lowest as seen at the rate estimated so far, which a second of drift would bias).
        offsets = bounds_s - slots * self.period_s
        early = np.flatnonzero(bounds_s < bounds_s[0] + 1.0)
        late = np.flatnonzero(bounds_s > bounds_s[-1] - 1.0)
        first, last = early[np.argmin(offsets[early])], late[np.argmin(offsets[late])]
        rate = (bounds_s[last] - bounds_s[first]) / (slots[last] - slots[first])
        self.period_s = float(np.clip(rate, self._nominal_s * (1.0 - self.MAX_RATE_ERROR),
                                      self._nominal_s * (1.0 + self.MAX_RATE_ERROR)))

    def time_s(self, slot: float) -> float:
        """
        Return when the sample in a slot was measured.

        :param slot: the sample's stream slot (after at least one :meth:`add`)
        :return: monotonic time, s
        """
        slots, bounds_s = np.array(self._bounds).T
        recent = bounds_s >= bounds_s[-1] - self.WINDOW_S
        return float(np.min(bounds_s[recent] - slots[recent] * self.period_s)
                     + slot * self.period_s)


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
    :ivar device_time_us: the first sample's time on the device's clock, microseconds (its
        frame's timestamp plus its place in the frame; a 32-bit clock unwrapped), for formats
        that carry one (ultra-dense and HQ capsules), then also what ``first_sample_s`` is read
        from; None when the format has none or none of the turn's frames had a readable one
    """

    angle_deg: np.ndarray
    distance_mm: np.ndarray
    quality: np.ndarray
    first_sample_s: float
    period_s: float
    last_byte_s: float
    device_time_us: Optional[float] = None


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
        self._clock = SampleClock(self._sample_s)
        self._device_clock = SampleClock(1e-6)     # slots: the device's microseconds
        self._last_frame_us = None                  # the last frame timestamp, unwrapped
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
        # A corrected angle (express and ultra capsules) may lie a few degrees before the grid
        # angle whose wrap the S flag marks: a flag just before 360 degrees starts a turn too.
        flagged = samples.start & ((drop > 0.0) | (angle > 360.0 - _CORRECTION_SPAN_DEG))
        boundary = flagged | (drop > _MISSED_START_DROP_DEG)
        if self._step_deg is not None and not first:
            swept_deg = np.diff(samples.slot, prepend=self._last_slot) * self._step_deg
            # Wraps between consecutive samples by their slots; a fall in angle already shows
            # one (and is judged above), so only wraps the angles cannot show count here.
            wraps = np.floor((swept_deg + drop) / 360.0 + 0.5)
            boundary |= wraps >= 1.0 + (drop > 0.0)
        cuts = self._without_echoes(np.flatnonzero(boundary), flagged, angle)
        self._last_angle = angle[-1]
        self._last_slot = samples.slot[-1]
        self._clock.add(samples.slot, measured_s)
        device_us = self._sample_device_times_us(samples)
        timed = device_us >= 0
        if timed.any():
            self._device_clock.add(device_us[timed], measured_s[timed])
        columns = (angle, samples.distance_mm, samples.quality, samples.slot, received_s,
                   device_us)
        turns = []
        begin = 0
        for cut in cuts:
            self._append(columns, begin, cut)
            turn = self._close()
            if turn is not None:
                turns.append(turn)
            begin = cut
        self._append(columns, begin, len(angle))
        return turns

    def _without_echoes(self, cuts: np.ndarray, flagged: np.ndarray, angle: np.ndarray) -> list:
        """
        Drop an unflagged turn boundary less than a quarter turn after the previous one.

        Corrected angles scatter about the sample grid: near the wrap a turn's samples may
        fall below 360 degrees and rise again (0.2, 359.6, 0.6), falls that are no new turn.

        :param cuts: indices of the boundaries found in this chunk
        :param flagged: True where the S flag marks a boundary
        :param angle: the chunk's angles, degrees
        :return: the indices kept
        """
        step_deg = self._step_deg
        if step_deg is None:
            rises = np.diff(angle)
            rises = rises[(rises > 0.0) & (rises < _CORRECTION_SPAN_DEG)]
            step_deg = float(np.median(rises)) if rises.size else None
        if step_deg is None:
            return list(cuts)
        quarter = 90.0 / step_deg
        kept, last = [], -self._size
        for cut in cuts:
            if flagged[cut] or cut - last >= quarter:
                kept.append(cut)
                last = cut
        return kept

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
        angle, distance, quality, slot, received_s, device_time_us = (
            np.concatenate(c) for c in zip(*parts))
        steps = np.diff(angle)
        steps = steps[steps > 0.0]
        if not steps.size:
            self.dropped_turns += 1
            return None
        self._step_deg = step_deg = float(np.median(steps))
        period_s = 360.0 / step_deg * self._clock.period_s
        first_sample_s = self._clock.time_s(int(slot[0]))
        first_device_us = None
        timed = np.flatnonzero(device_time_us >= 0)
        if timed.size:
            # The first sample with a device time, back to the turn's first by the samples
            # between (its own frame's timestamp may have been unreadable).
            j = timed[0]
            first_device_us = float(device_time_us[j] - (slot[j] - slot[0]) * self._sample_s * 1e6)
            first_sample_s = self._device_clock.time_s(first_device_us)
        self._turn_end_s = first_sample_s + (2.0 - angle[0] / 360.0) * period_s
        return Turn(angle_deg=angle, distance_mm=distance, quality=quality,
                    first_sample_s=first_sample_s, period_s=period_s,
                    last_byte_s=float(received_s[-1]), device_time_us=first_device_us)

    def _sample_device_times_us(self, samples: Samples) -> np.ndarray:
        """
        Return each sample's time on the device's clock, -1 where its frame has none.

        A frame's timestamp is its first sample's; a decoder publishes whole frames, so a
        sample's place in its frame is the first's ``samples_after`` less its own.

        :param samples: decoded samples in stream order
        :return: microseconds on the device's clock, unwrapped
        """
        frame_us = samples.device_time_us
        known = np.flatnonzero(frame_us >= 0)
        if not known.size:
            return np.full(len(frame_us), -1.0)
        starts = np.flatnonzero(np.r_[True, np.diff(samples.frame_end) != 0])
        first_after = np.repeat(np.maximum.reduceat(samples.samples_after, starts),
                                np.diff(np.r_[starts, len(frame_us)]))
        place = first_after - samples.samples_after
        raw = frame_us[known].astype(np.int64)
        last = int(raw[0]) if self._last_frame_us is None else self._last_frame_us
        # Each timestamp continues the one before by their difference modulo the 32-bit
        # clock's range (a 64-bit one's frames lie far less than that apart).
        half = _DEVICE_TIME_WRAP_US // 2
        steps = (np.diff(np.r_[last, raw]) + half) % _DEVICE_TIME_WRAP_US - half
        unwrapped = last + np.cumsum(steps)
        self._last_frame_us = int(unwrapped[-1])
        device_us = np.full(len(frame_us), -1.0)
        device_us[known] = unwrapped + place[known] * self._sample_s * 1e6
        return device_us


def sweep_deg(angle_deg: np.ndarray) -> float:
    """
    Return the raw angle a run of samples sweeps, each step taken the short way round.

    A sample repeated or out of order steps back and is taken back; only a run of more than a
    rotation sweeps more than 360 degrees.

    :param angle_deg: raw angles in measurement order, degrees
    :return: degrees from the first sample to the last
    """
    return float(np.sum(np.mod(np.diff(angle_deg) + 180.0, 360.0) - 180.0))


class PublishGate:
    """
    Pass the turns that are one rotation a damaged stream cannot have made up, one per rotation.

    A turn passes when its samples sweep (:func:`sweep_deg`) at least :data:`MIN_SWEEP_DEG`
    (false turn boundaries, which garbage angles make, cut fragments that would be published
    many times a rotation) and at most :data:`MAX_TURN_SHARE` of a rotation (a missed boundary
    would publish two rotations as one), and when it starts at least :data:`MIN_PERIOD_SHARE`
    of its rotation period after the last turn passed (two fragments of one rotation are not
    published as two scans).
    """

    def __init__(self):
        self._last_start_s = -math.inf

    def admit(self, turn: Turn) -> bool:
        """
        Tell whether to publish a turn (and remember it when so).

        :param turn: the next assembled turn
        :return: True to publish it
        """
        sweep = sweep_deg(turn.angle_deg) if len(turn.angle_deg) > 1 else 0.0
        admitted = bool(MIN_SWEEP_DEG <= sweep <= 360.0 * MAX_TURN_SHARE
                        and turn.first_sample_s - self._last_start_s
                        >= MIN_PERIOD_SHARE * turn.period_s)
        if admitted:
            self._last_start_s = turn.first_sample_s
        return admitted
