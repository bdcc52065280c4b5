# Copyright 2026 wctls_ros maintainers
# SPDX-License-Identifier: Apache-2.0

"""
Capsule framing shared by every RPLIDAR capsule format (pure).

Where capsules begin, which arrived short, and which start angles to believe. The capsule
answers (0x82 express and 0x85 dense, 84 bytes; 0x84 ultra and 0x86 ultra-dense,
132 bytes) share their first four bytes: the sync nibbles A and 5, each beside a checksum
nibble, and a u16 start angle (1/64 degree, bit 15 the S flag). A capsule's samples lie between
its start angle and its successor's, so every format decodes a capsule once the next has
arrived; only the bytes after the start angle differ. What lost bytes do to that layout is
common to them all, and handled here:

- :class:`CapsuleFramer` cuts the stream into regions between two headers. A capsule cut short
  (a run of lost bytes up to its end: a lost USB packet, an overrun buffer) is followed at once
  by the next one: a header within the capsule whose start angle lies one sweep on starts the
  next capsule (a false header among the samples has a random angle). A region that lost a few
  bytes per capsule lost them one by one, one that lost more lost a run (:attr:`Region.cut`),
  and a region longer than its capsules was framed on a false header (:attr:`Region.overlong`):
  a line loses bytes, it does not add them.
- :class:`AngleTrack` decides each capsule's start angle from its field, its successor's and
  the sweep of the capsules before, and counts capsules lost without a trace.
- :func:`placeable`: a capsule whose start angle is out of sequence is not placed at the
  predicted one when that may be wrong too.

A decoder of a capsule format keeps a :class:`CapsuleFramer` and an :class:`AngleTrack`, reads
the samples of each region (realigning those of a region that lost bytes, which depends on the
format's layout; an overlong region's are unreadable), places each capsule with a
:class:`CapsulePlacer` and publishes only what :func:`placeable` allows: see
:class:`~wctls_rplidar.capsules.DenseCapsuleDecoder` and
:class:`~wctls_rplidar.checked.CheckedCapsuleDecoder`.
"""

import collections
from dataclasses import dataclass
import math
from typing import NamedTuple, Optional

import numpy as np

from .protocol import FULL_TURN_Q6

FULL_TURN_Q8 = FULL_TURN_Q6 << 2

# Bytes per 84-byte capsule that framing and realignment follow (at 5 % lost bytes, 0.04 % of
# the capsules lose more; a region that lost more lost a run of them), and capsules between two
# headers: up to two damaged headers in a row when bytes were lost, up to seven when the
# spacing is exact.
_MAX_SHIFT_PER_84 = 12
_MAX_REGION = 3
_MAX_EXACT_REGION = 8
# Angles: tolerance for a suspect start angle (1/8 degree), the share of a sweep allowed for one
# whose checksum passed, and how far (capsules, about a turn) a prediction reaches.
_ANGLE_TOLERANCE_Q8 = 32
# A header starts the capsule a whole number of sweeps on within this (1/256 degree) plus this
# share of a sweep per capsule: bytes gained before it are a contradiction (CapsuleFramer).
_GAIN_TOLERANCE_Q8 = 32
_GAIN_SWEEP_SHARE = 128
# Steps between headers that must be found (and most of them agree) to stand for the sweep.
_STEPS_AGREEING = 3
_CLEAN_ANGLE_SHARE = 8
_PREDICTION_REACH = 24
# A prediction this few capsules old outranks a run of two observed angles; after this many
# start angles in a row not believed, the sweep is measured anew; measured sweeps refine the
# tracked one with this weight.
_FRESH_GAP = 2
_RESTART_AFTER = 8
_SWEEP_WEIGHT = 1.0 / 8.0
# Capsules compared with their predecessors for repeats, and capsules every one is suspect for
# after a sign of damage the checksum cannot see (CapsulePlacer).
_REPEAT_WINDOW = 32
_UNSEEN_DAMAGE_MEMORY = 1024
# Contradictions within that many capsules that say a line gains or moves bytes (a false header
# in sequence makes one every few thousand capsules on a line that corrupts or loses bytes).
_MOVED_BYTES_EVIDENCE = 3
# The line counts as damaged while this share of the recent capsules fails (weight 1/32).
_DAMAGED_SHARE = 0.5
_DAMAGE_WEIGHT = 1.0 / 32.0
# The share of bytes damaged from which nothing is published (ByteDamage): there so many samples
# are damaged that their neighbours' agreement vouches for wrong ones (at 10 % corrupted bytes
# 0.1-0.3 % of the samples published were wrong, at 20 % 10-45 %). It is judged on an upper
# bound, this many standard errors above, of the share of broken headers.
WITHHELD_BYTE_DAMAGE = 0.08
_BOUND_ERRORS = 1.0
# Capsules a measurement of the damage spans (a running mean up to it, then a decaying one: a
# few seconds of capsules).
_BYTE_DAMAGE_MEMORY = 256
_BYTE_DAMAGE_FIRST = 32
_BYTE_DAMAGE_FIRST_HEADERS = 8
# A corrupted byte keeps its sync nibble with probability 15/255.
_NIBBLE_CHANGED = 240.0 / 255.0


def wrap_q8(angle_q8: int) -> int:
    """Return an angle difference in 1/256 degree wrapped into [-180, 180) degrees."""
    return (angle_q8 + FULL_TURN_Q8 // 2) % FULL_TURN_Q8 - FULL_TURN_Q8 // 2


class Region(NamedTuple):
    """
    Capsules between two headers.

    :ivar pos: index of its first header in the bytes held
    :ivar count: capsules it holds (headers between them may be damaged)
    :ivar end: index of the header after it
    :ivar slot: stream index of its first capsule
    :ivar lost: bytes it lost: its capsules' bytes minus its length (negative: too long)
    :ivar cut: it lost more bytes than scattered losses take (12 per 84-byte capsule, 6 per
        further one: they average out over capsules): a run of them
    :ivar tangled: the start angles of its headers say it gained bytes or holds them out of
        order (see :meth:`CapsuleFramer._gained`)
    """

    pos: int
    count: int
    end: int
    slot: int
    lost: int
    cut: bool
    tangled: bool = False

    @property
    def overlong(self) -> bool:
        """Tell whether it is longer than its capsules: framed on a false header."""
        return self.lost < 0

    @property
    def unreadable(self) -> bool:
        """Tell whether its samples cannot be read: overlong or tangled."""
        return self.lost < 0 or self.tangled


@dataclass(frozen=True)
class LinkDamage:
    """
    What a stream decoder measured of its link's damage, for diagnostics.

    :ivar byte_share: the share of the stream's bytes damaged (corrupted, lost or gained), as
        the decoder measures it (capsule formats: :class:`ByteDamage`; HQ capsules: the top
        bytes of their distances); None for a format that does not measure it (standard nodes)
    :ivar withheld: the samples last decoded were withheld (published as no return), the line
        too damaged to vouch for them: from :data:`WITHHELD_BYTE_DAMAGE` on in the capsule
        formats, beyond the sequence checks' reach in standard nodes
    """

    byte_share: Optional[float] = None
    withheld: bool = False


class ByteDamage:
    """
    The share of a capsule stream's bytes damaged: corrupted, lost or gained.

    Corrupted: from the sync nibbles at every capsule's place in regions that neither lost nor
    gained bytes. A capsule's place is its region's first header (found) or one within the
    region (missed), so the nibbles read there are a fair sample of every header's; both
    survive with probability ``(1 - p * 240 / 255)^2`` for a share ``p`` of bytes corrupted at
    random. Lost or gained: the bytes a region lacks or has over its capsules', per byte.
    """

    def __init__(self):
        self._broken = 0.0          # share of headers broken (mean over the memory)
        self._headers = 0
        self._moved = 0.0           # share of bytes lost or gained (mean over the memory)
        self._capsules = 0

    @property
    def share(self) -> float:
        """Return the share of bytes damaged (corrupted plus lost or gained)."""
        return self._corrupted(self._broken) + self._moved

    @property
    def measured(self) -> bool:
        """Tell whether enough capsules were framed (:data:`_BYTE_DAMAGE_FIRST`) to measure."""
        return self._capsules >= _BYTE_DAMAGE_FIRST

    def withheld(self, doubtful: bool) -> bool:
        """
        Tell whether the line may damage too many bytes for a suspect sample to be published.

        Until :data:`_BYTE_DAMAGE_FIRST` capsules were framed, there is no evidence either way:
        withheld where three in four capsules at hand failed their checksums, or where
        :data:`_BYTE_DAMAGE_FIRST_HEADERS` headers read twice the share withheld. Then, where they
        did, judged on an upper bound of the share of broken headers (a broken one added to the
        evidence, :data:`_BOUND_ERRORS` standard error above), elsewhere on the share measured.
        Where few capsules keep their length (a line that loses bytes) their headers bound
        nothing: there the share measured counts.

        :param doubtful: three in four of the capsules at hand failed their checksums
        """
        if not self.measured:
            return doubtful or (self._headers >= _BYTE_DAMAGE_FIRST_HEADERS
                                and self.share >= 2.0 * WITHHELD_BYTE_DAMAGE)
        broken = self._broken
        if doubtful and 4 * self._headers >= self._capsules:
            seen = min(self._headers, _BYTE_DAMAGE_MEMORY)
            broken = (broken * seen + 1.0) / (seen + 2.0)
            broken = min(broken + _BOUND_ERRORS * math.sqrt(
                broken * (1.0 - broken) / max(seen, 1)), 1.0)
        return self._corrupted(broken) + self._moved >= WITHHELD_BYTE_DAMAGE

    @staticmethod
    def _corrupted(broken: float) -> float:
        """Return the share of bytes corrupted that breaks this share of headers."""
        return (1.0 - math.sqrt(1.0 - broken)) / _NIBBLE_CHANGED

    def take(self, headers: np.ndarray, capsules: int, moved_bytes: int, size: int):
        """
        Take the evidence of the regions one chunk completed.

        :param headers: the first two bytes at each capsule's place in the regions that kept
            their length, shape (n, 2), uint8
        :param capsules: capsules in all regions
        :param moved_bytes: bytes lost or gained by all regions
        :param size: bytes per capsule
        """
        if len(headers):
            broken = ((headers[:, 0] >> 4) != 0xA) | ((headers[:, 1] >> 4) != 0x5)
            self._headers += len(headers)
            self._broken += (np.mean(broken) - self._broken) * min(
                len(headers) / min(self._headers, _BYTE_DAMAGE_MEMORY), 1.0)
        if capsules:
            self._capsules += capsules
            self._moved += (moved_bytes / (capsules * size) - self._moved) * min(
                capsules / min(self._capsules, _BYTE_DAMAGE_MEMORY), 1.0)


class CapsuleFramer:
    """
    Cuts a capsule stream into regions between headers, resynchronising capsule by capsule.

    :param capsule_size: bytes per capsule
    :param angles: the stream's start angle track (its sweep tells a capsule arriving early)
    :param counts: the decoder's counters (``StreamCounts`` fields), updated in place: frames
        and lost frames in gaps, resyncs, discarded bytes
    :param angle_at: the start angle's offset in the capsule, bytes (2; 8 in the ultra-dense
        capsule, after its timestamp and status)
    """

    def __init__(self, capsule_size: int, angles: 'AngleTrack', counts: dict,
                 angle_at: int = 2):
        self._size = capsule_size
        self._angle_at = angle_at
        self._head = angle_at + 2       # bytes up to the end of the start angle
        self._max_shift = round(_MAX_SHIFT_PER_84 * capsule_size / 84)
        self._angles = angles
        self._counts = counts
        self._buffer = b''
        self._offset = 0            # stream offset of _buffer[0]
        self._synced = False        # _buffer[0] starts a capsule header
        self._slot = 0              # capsule index of the capsule at _buffer[0]
        self._gap_from = None       # stream offset where sync was lost
        # Regions whose start angles said bytes were gained or a header repeated: what a line
        # that loses and corrupts bytes never does (CapsulePlacer reads it).
        self.contradictions = 0
        self._after_contradiction = False   # the last region contradicted its start angles
        self._known_sweep_q8 = None     # the last sweep known (see _sweep_q8)
        self.damage = ByteDamage()

    def split(self, data: bytes) -> tuple:
        """
        Take the next received chunk; return the regions it completes.

        A region is complete once the header and start angle after it have arrived.

        :param data: the next received bytes, any length
        :return: ``(raw, regions, offset)``: the bytes held, ``raw[0]`` at stream offset
            ``offset`` (the header and start angle after the last region included), and the
            complete regions, a list of :class:`Region`
        """
        buffer = self._buffer + bytes(data)
        raw = np.frombuffer(buffer, np.uint8)
        headers = ((raw[:-1] >> 4) == 0xA) & ((raw[1:] >> 4) == 0x5)
        regions = []
        pos = 0
        while True:
            if not self._synced:
                found = np.flatnonzero(headers[pos:])
                if not found.size:
                    keep = max(len(buffer) - 1, pos)      # a header may begin in the last byte
                    self._counts['discarded_bytes'] += keep - pos
                    pos = keep
                    break
                pos = self._regain_sync(pos, pos + int(found[0]))
            seen = self.contradictions
            step = self._next_header(raw, headers, pos)
            if step is None:
                break
            count, end, tangled = step
            if count == 0 and end is not None:
                # The header at ``end`` repeats this one's start angle: the bytes from here to
                # it are a copy of the capsule's first bytes (a packet delivered twice).
                self._counts['discarded_bytes'] += end - pos
                pos = end
                continue
            if count == 0:
                # No header where the next capsules should begin: this one leads nowhere.
                self._synced = False
                self._gap_from = self._offset + pos
                self._counts['resyncs'] += 1
                self._counts['discarded_bytes'] += 1
                pos += 1
                continue
            lost = count * self._size - (end - pos)
            if self._after_contradiction and not (count == 1 and not lost and not tangled):
                # Its first header may be one a packet moved: its bytes are no better.
                tangled = True
            self._after_contradiction = self.contradictions != seen
            regions.append(Region(pos, count, end, self._slot, lost,
                                  2 * lost > (count + 1) * self._max_shift, tangled))
            self._slot += count
            pos = end
        kept = [r.pos + self._size * j for r in regions if not r.lost
                for j in range(r.count)]
        self.damage.take(raw[np.array(kept, np.int64)[:, None] + np.arange(2)],
                         sum(r.count for r in regions),
                         # A run of lost bytes (a capsule cut short) counts as twice the most
                         # bytes scattered losses take: its loss is seen, theirs are not.
                         sum(min(max(r.lost, 0), (r.count + 1) * self._max_shift)
                             for r in regions if not r.tangled),
                         self._size)
        offset = self._offset
        self._buffer = buffer[pos:]
        self._offset += pos
        return raw, regions, offset

    def angle_field(self, raw: np.ndarray, pos: int) -> int:
        """
        Read the start angle field (with the S flag) of the capsule whose header is at ``pos``.

        :param raw: the received bytes
        :param pos: the capsule's first byte
        :return: the u16 field
        """
        at = pos + self._angle_at
        return int(raw[at]) | int(raw[at + 1]) << 8

    def slip(self, capsules: int):
        """
        Count capsules the stream lost (or counted) without a trace in its bytes.

        :param capsules: capsules to add to the stream index (negative: counted too many)
        """
        self._slot += capsules

    def _regain_sync(self, pos: int, header: int) -> int:
        """Skip to a header found byte by byte; count the capsules the gap held as lost."""
        self._counts['discarded_bytes'] += header - pos
        self._synced = True
        if self._gap_from is not None:
            lost = max(round((self._offset + header - self._gap_from) / self._size), 1)
            self._slot += lost
            self._counts['frames'] += lost
            self._counts['lost_frames'] += lost
            self._gap_from = None
        return header

    def _next_header(self, raw: np.ndarray, headers: np.ndarray, pos: int):
        """
        Find where the capsules after the one at ``pos`` end.

        :return: ``(n, end, tangled)``: n capsules end at the header at ``end``, their bytes
            tangled or not (see :meth:`_gained`); ``(0, None, False)`` when no header lies where
            one should; ``(0, end, False)`` when the header at ``end`` repeats this one; None
            until enough bytes have arrived
        """
        step = self._spaced_header(raw, headers, pos)
        if step == (1, pos + self._size):
            # One capsule between headers its size apart: nothing to doubt in its framing (a
            # false header among its samples has a random start angle).
            return 1, pos + self._size, False
        repeat = self._repeated(raw, headers, pos)
        if repeat is not None:
            self.contradictions += 1
            return 0, repeat, False
        if step is None or step[1] is None:
            return None if step is None else (0, None, False)
        return self._gained(raw, headers, pos, *step)

    def _repeated(self, raw: np.ndarray, headers: np.ndarray, pos: int) -> Optional[int]:
        """
        Find a header within a capsule after this one with its start angle: a copy of it.

        :return: its index, None when there is none
        """
        last = min(pos + self._size, raw.size - self._head)
        if last <= pos:
            return None
        this = start_q8(self.angle_field(raw, pos))
        if this is None:
            return None
        for at in (np.flatnonzero(headers[pos + 1:last + 1]) + pos + 1).tolist():
            following = start_q8(self.angle_field(raw, at))
            if following is not None and abs(wrap_q8(following - this)) <= _GAIN_TOLERANCE_Q8:
                return at
        return None

    def _gained(self, raw: np.ndarray, headers: np.ndarray, pos: int, count: int, end: int):
        """
        Check a region whose headers are not a capsule apart against their start angles.

        A header whose start angle lies ``m`` sweeps on from this one's (within
        :data:`_GAIN_TOLERANCE_Q8` plus a share of a sweep per capsule), less than a capsule from
        where ``m`` capsules would put it, starts the capsule ``m`` on. Along the stream those
        headers must follow in order of ``m``, each at most its capsules' bytes after the one
        before: bytes are lost, never gained. Where they are not
        (a USB packet delivered twice, or swapped with the next: its headers move by a packet),
        the spacing of headers alone would read capsules that lost bytes, or intact capsules
        with another's bytes among theirs: the region is tangled (unreadable), and holds the
        capsules its last header's start angle says. Otherwise the first of those headers ends
        the region, holding ``m`` capsules. A first header with this one's start angle
        (``m = 0``) repeats it: what lies before it is a copy. ``m`` is at most
        :data:`_MAX_EXACT_REGION`.

        :param raw: the received bytes
        :param headers: where sync nibbles are
        :param pos: this capsule's header
        :param count: capsules the spacing of headers gives the region
        :param end: the header after the region
        :return: ``(count, end, tangled)``, ``count`` corrected; ``(0, end, False)`` when the
            header at ``end`` repeats this one
        """
        sweep_q8 = self._sweep_q8(raw, headers)
        this = start_q8(self.angle_field(raw, pos))
        if this is None:
            return count, end, False
        previous_at, previous_m, tangled, end_m, first = pos, 0, False, None, None
        for at in (np.flatnonzero(headers[pos + 1:end + 1]) + pos + 1).tolist():
            following = start_q8(self.angle_field(raw, at))
            if following is None:
                continue
            ahead = (following - this + _GAIN_TOLERANCE_Q8) % FULL_TURN_Q8 - _GAIN_TOLERANCE_Q8
            capsules = round(ahead / sweep_q8)
            if not (0 <= capsules <= _MAX_EXACT_REGION and abs(ahead - capsules * sweep_q8)
                    <= _GAIN_TOLERANCE_Q8 + capsules * sweep_q8 / _GAIN_SWEEP_SHARE
                    and abs(at - pos - capsules * self._size) < self._size):
                continue        # not in sequence, or too far from its place to be moved
            if capsules == 0 and previous_at == pos:
                self.contradictions += 1
                return 0, at, False
            tangled |= (capsules <= previous_m
                        or at - previous_at > (capsules - previous_m) * self._size)
            first = first or (capsules, at)
            previous_at, previous_m = at, capsules
            end_m = capsules if at == end else None
        if tangled:
            self.contradictions += 1
            return end_m or count, end, True
        if first is not None:
            # The first header in sequence ends the region (what the spacing alone found after it
            # may be a capsule on); a region that lost a run of bytes.
            return first[0], first[1], False
        return count, end, False

    def _headers_sweep_q8(self, raw: np.ndarray, headers: np.ndarray) -> Optional[float]:
        """
        Return the sweep the headers received show, before the angle track has measured one.

        Each pair of consecutive headers about ``n`` capsules apart (within the bytes those may
        lose) steps ``n`` sweeps; the median step stands for the sweep when most steps agree
        with it (headers a line moved or a false header's disagree).

        :param raw: the received bytes
        :param headers: where sync nibbles are
        :return: 1/256 degree; None without enough agreement
        """
        at = np.flatnonzero(headers[:max(raw.size - self._head + 1, 0)])
        if at.size < _STEPS_AGREEING + 1:
            return None
        fields = raw[at + self._angle_at].astype(np.int64) | (
            raw[at + self._angle_at + 1].astype(np.int64) << 8)
        angles = (fields & 0x7FFF) << 2
        spacing = np.diff(at)
        capsules = np.maximum(np.rint(spacing / self._size), 1)
        fits = ((np.abs(spacing - capsules * self._size) <= capsules * self._max_shift)
                & (capsules <= _MAX_REGION) & (angles[1:] < FULL_TURN_Q8)
                & (angles[:-1] < FULL_TURN_Q8))
        steps = (np.diff(angles) % FULL_TURN_Q8)[fits] / capsules[fits]
        if steps.size < _STEPS_AGREEING:
            return None
        median = float(np.median(steps))
        agreeing = np.abs(steps - median) <= _ANGLE_TOLERANCE_Q8
        return median if median > 0 and 2 * np.count_nonzero(agreeing) > steps.size else None

    def _sweep_q8(self, raw: np.ndarray, headers: np.ndarray) -> float:
        """
        Return the sweep the angle track measured, else the one the headers show.

        :return: 1/256 degree; the last one known while neither is; the nominal one before any
        """
        measured = self._angles.measured_sweep_q8()
        if measured is None and self._known_sweep_q8 is None:
            measured = self._headers_sweep_q8(raw, headers)
        # The last one known stands in while the angle track starts over; before any, the
        # nominal one (as for a capsule cut short).
        self._known_sweep_q8 = measured or self._known_sweep_q8
        return self._known_sweep_q8 or self._angles.sweep_deg() * 256.0

    def _spaced_header(self, raw: np.ndarray, headers: np.ndarray, pos: int):
        """
        Find where the capsules after the one at ``pos`` end, by the spacing of headers.

        :return: ``(n, end)``: n capsules end at the header at ``end``; ``(0, None)`` when no
            header lies where one should; None until enough bytes have arrived
        """
        size = raw.size
        for count in range(1, _MAX_EXACT_REGION + 1):
            expected, reach = pos + count * self._size, count * self._max_shift
            exact = expected + self._head <= size and headers[expected]
            if count == 1 and expected + self._head <= size and not (
                    exact and self._follows(raw, pos, expected)):
                # A header in sequence wins over one merely a capsule on, which may lie in the
                # distances of a successor that arrived early. Two sweeps on, after a run of
                # lost bytes, the successor was cut short within its own header.
                early = np.flatnonzero(headers[pos + 1:expected]) + pos + 1
                for sweeps, before in ((1, expected), (2, expected - reach)):
                    following = [at for at in early
                                 if at < before and self._follows(raw, pos, at, sweeps)]
                    if following:
                        return sweeps, int(following[0])
            if exact:
                return count, expected
            if count > _MAX_REGION:
                # Beyond a few capsules only an exact spacing is evidence enough.
                if expected + self._head > size:
                    return None
                continue
            if expected + reach + self._head > size:
                return None
            near = np.flatnonzero(headers[expected - reach:expected + reach + 1])
            if near.size:
                near += expected - reach
                return count, int(near[np.argmin(np.abs(near - expected))])
        return 0, None

    def _follows(self, raw: np.ndarray, pos: int, at: int, sweeps: int = 1) -> bool:
        """
        Tell whether the header at ``at`` starts the capsule ``sweeps`` after the one at ``pos``.

        Any run of lost bytes shortens a capsule, up to all but its first byte: a header
        anywhere within it starts the next capsule when its start angle lies one sweep on (a
        false header in the distances has a random one).

        :param raw: the received bytes
        :param pos: a capsule header
        :param at: a later header
        :param sweeps: capsules on
        :return: True when its start angle follows at the tracked sweep
        """
        this = start_q8(self.angle_field(raw, pos))
        following = start_q8(self.angle_field(raw, at))
        if this is None or following is None:
            return False
        sweep_q8 = self._angles.sweep_deg() * 256.0
        return (abs(wrap_q8(following - this - round(sweeps * sweep_q8)))
                <= sweep_q8 / _CLEAN_ANGLE_SHARE)


class CapsulePlacer:
    """
    Places a decoder's capsules in angle, in stream order, with its :class:`AngleTrack`.

    It follows how damaged the line is: while most recent capsules fail their checksum, a
    passing one vouches for nothing (1 in 256 damaged capsules passes the 8-bit checksum), and
    every capsule is suspect. A line can also damage capsules in ways the checksum cannot see:
    two bit flips at one bit position, or bytes swapped within a capsule (an XOR checksum does
    not see the order of bytes). Such a line shows it in the capsules it leaves legible: an
    intact capsule out of sequence (a start angle flipped, a copy of an earlier capsule) or
    with an S flag after the first, a header whose start angle says bytes were gained
    (:attr:`CapsuleFramer.contradictions`), two bits flipped at one position that the
    decoder's samples show (:meth:`note_unseen_damage`). For
    :data:`_UNSEEN_DAMAGE_MEMORY` capsules after such a sign every capsule is suspect, its
    samples checked as those of a damaged one. A line that gains or moves bytes can also put
    another capsule's samples into a damaged one where its framing and start angle are right,
    and those samples are plausible among themselves: for as many capsules after
    :data:`_MOVED_BYTES_EVIDENCE` contradictions within as many, a capsule that failed its
    checksum is not published at all (its placement withdrawn). A capsule identical to one of
    the last :data:`_REPEAT_WINDOW` slots, and less than a turn, before it (a frame or USB
    buffer sent again) is taken out of the stream: the
    capsules after it move back a slot, and it does not restart the angle track with the S
    flag of the first capsule it may copy.

    :param angles: the stream's start angle track
    :param framer: the stream's framer (told of capsules lost without a trace)
    :param counts: the decoder's counters (``StreamCounts`` fields), updated in place: frames
        and lost frames found from the start angles, replaced angles
    """

    def __init__(self, angles: 'AngleTrack', framer: CapsuleFramer, counts: dict):
        self._angles = angles
        self._framer = framer
        self._counts = counts
        self._damage = 0.0
        self._recent = collections.deque()     # (slot, bytes) of recent intact capsules
        self._contradictions = 0
        self._since_unseen_damage = _UNSEEN_DAMAGE_MEMORY
        self._weak_sign_at = -math.inf          # when (in capsules placed) one was last taken
        self._placed = 0                        # capsules placed so far
        self._contradicted = collections.deque()   # when (in capsules placed) they were
        self._moved_bytes_until = 0

    def note_unseen_damage(self):
        """Take a sign of damage the checksum cannot see that the samples showed."""
        self._since_unseen_damage = 0

    def shows_damage(self) -> bool:
        """
        Tell whether the line showed damage lately: any the checksum sees or cannot see.

        Bytes damaged (:attr:`CapsuleFramer.damage`), most recent capsules failing, a sign of
        damage the checksum cannot see (:meth:`note_unseen_damage`) or a weak one
        (:meth:`note_weak_sign`) within :data:`_UNSEEN_DAMAGE_MEMORY` capsules.
        """
        return (self._framer.damage.share > 0.0 or self._damage > _DAMAGED_SHARE
                or self._since_unseen_damage < _UNSEEN_DAMAGE_MEMORY
                or self._placed - self._weak_sign_at <= _UNSEEN_DAMAGE_MEMORY)

    def note_weak_sign(self):
        """Take a sign of damage the checksum cannot see too weak to believe on a clean line."""
        self._weak_sign_at = self._placed

    def place(self, frames: list, next_field: int):
        """
        Place each capsule, in stream order.

        :param frames: the capsules, records with ``slot``, ``angle_field``, ``clean``
            (checksum passed) and ``key`` (its bytes when whole, else None) read,
            ``placement`` (:class:`Placement`) set and ``suspect`` raised here; ``slot`` moves
            on by the capsules lost before it without a trace (back by the repeats before it)
        :param next_field: the start angle field of the capsule after the last
        """
        if self._framer.contradictions != self._contradictions:
            self._contradicted.extend([self._placed] * (self._framer.contradictions
                                                        - self._contradictions))
            self._contradictions = self._framer.contradictions
            self._since_unseen_damage = 0
            while self._contradicted[0] < self._placed - _UNSEEN_DAMAGE_MEMORY:
                self._contradicted.popleft()
            if len(self._contradicted) >= _MOVED_BYTES_EVIDENCE:
                # Not a false header's chance: the line gains or moves bytes.
                self._moved_bytes_until = self._placed + _UNSEEN_DAMAGE_MEMORY
        # Within less than a turn: a still scene seen by a noiseless device repeats a turn on.
        window = min(_REPEAT_WINDOW, int(FULL_TURN_Q8 / (256.0 * self._angles.sweep_deg())) - 1)
        for frame in frames:
            if frame.key is None or not frame.clean:
                continue
            while self._recent and self._recent[0][0] < frame.slot - window:
                self._recent.popleft()
            if any(key == frame.key for _, key in self._recent):
                frame.placement = Placement(None, None, False, -1)
                frame.suspect = True
                self._since_unseen_damage = 0
            else:
                self._recent.append((frame.slot, frame.key))
        slip = 0
        for i, frame in enumerate(frames):
            if frame.placement is not None:
                slip -= 1                   # a repeat: the capsules after it move back
                continue
            self._damage += _DAMAGE_WEIGHT * ((not frame.clean) - self._damage)
            damaged_line = self._damage > _DAMAGED_SHARE
            unseen_damage = self._since_unseen_damage < _UNSEEN_DAMAGE_MEMORY
            moved_bytes = self._placed < self._moved_bytes_until
            self._since_unseen_damage += 1
            self._placed += 1
            after = next((f for f in frames[i + 1:] if f.placement is None), None)
            frame.slot += slip
            # On a damaged line a passing checksum does not vouch for a start angle either.
            placement = self._angles.place(
                frame.slot, frame.angle_field, frame.clean and not damaged_line,
                after.slot + slip if after else frame.slot + 1,
                after.angle_field if after else next_field,
                bool(after) and after.clean and not damaged_line)
            if placement.slip:
                # Whole capsules the stream lost without a trace in its bytes (or that a
                # resync counted wrongly): the start angles tell how many.
                slip += placement.slip
                frame.slot += placement.slip
                self._counts['frames'] += max(placement.slip, 0)
                self._counts['lost_frames'] += max(placement.slip, 0)
            # Withdrawn after it served the angle track: bytes may have moved into it.
            frame.placement = placement if frame.clean or not moved_bytes else (
                Placement(None, None, placement.replaced, placement.slip))
            self._counts['replaced_angles'] += placement.replaced
            if frame.clean and not damaged_line and (
                    placement.replaced or (frame.angle_field & 0x8000 and self._placed > 1)):
                # Intact, yet out of sequence, or an S flag after the first capsule.
                self._since_unseen_damage = 0
            frame.suspect |= placement.replaced or damaged_line or unseen_damage
        self._framer.slip(slip)


def placeable(placement: 'Placement', clean: bool, region_cut: bool) -> bool:
    """
    Tell whether a capsule may be published where :class:`AngleTrack` placed it.

    A capsule whose start angle is out of sequence is placed at the predicted one, unless the
    prediction may be wrong too: an intact capsule out of sequence says the prediction lost
    count of capsules, and in a region that lost a run of bytes a capsule may be framed where
    none began (a short one's bytes read as its successor's).

    :param placement: the capsule's placement
    :param clean: its checksum passed
    :param region_cut: its region lost a run of bytes (:attr:`Region.cut`)
    :return: True when its samples may be published there
    """
    return (placement.start_q8 is not None and placement.sweep_q8 is not None
            and not (placement.replaced and (clean or region_cut)))


@dataclass(frozen=True)
class Placement:
    """
    A capsule's place in angle, as :class:`AngleTrack` decides it.

    :ivar start_q8: start angle, 1/256 degree; None when the capsule cannot be placed
    :ivar sweep_q8: angle its samples span, 1/256 degree; None when it cannot be placed
    :ivar replaced: the start angle is the predicted one, not the received one
    :ivar slip: capsules the stream lost unseen before this one (negative: counted too many)
    """

    start_q8: Optional[int]
    sweep_q8: Optional[float]
    replaced: bool
    slip: int


class AngleTrack:
    """
    The start angles of the capsules in sequence: which to believe and what to predict.

    :param max_sweep_q8: the largest plausible sweep of one capsule, 1/256 degree (the SDK's)
    :param nominal_sweep_q8: the sweep to expect until one is measured, 1/256 degree
    """

    def __init__(self, max_sweep_q8: int, nominal_sweep_q8: int):
        self._max_sweep_q8 = max_sweep_q8
        self._nominal_sweep_q8 = nominal_sweep_q8
        self._reference = None      # (slot, start) of the last believed start angle
        self._sweep = None          # one capsule's sweep, smoothed, 1/256 degree
        self._previous = None       # (slot, observed start) of the capsule before
        self._misses = 0            # start angles in a row not believed

    def sweep_deg(self) -> float:
        """Return one capsule's sweep, degrees (the nominal one until measured)."""
        return (self._sweep or self._nominal_sweep_q8) / 256.0

    def measured_sweep_q8(self) -> Optional[float]:
        """Return one capsule's sweep as measured, 1/256 degree; None until measured."""
        return self._sweep

    def place(self, slot: int, field: int, clean: bool, next_slot: int, next_field: int,
              next_clean: bool) -> tuple:
        """
        Decide a capsule's start angle and sweep from its field and its successor's.

        :param slot: the capsule's index in the stream
        :param field: its start angle field (bit 15: S)
        :param clean: its checksum passed on a line not otherwise damaged
        :param next_slot: the successor's index
        :param next_field: the successor's start angle field
        :param next_clean: the same of the successor (False when not known yet)
        :return: the :class:`Placement`
        """
        if clean and field & 0x8000 and not self._in_sequence(slot, field):
            # The device (re)started its stream here, as the SDK takes the S flag (one on a
            # start angle in sequence is a flipped bit: the stream goes on).
            self._reference = self._sweep = self._previous = None
        observed, following = start_q8(field), start_q8(next_field)
        tolerance = self._tolerance(clean)
        consecutive = next_slot == slot + 1
        ahead = None if observed is None or following is None or not consecutive else (
            (following - observed) % FULL_TURN_Q8)
        predicted, gap = self._predict(slot)
        matches = (observed is not None and predicted is not None
                   and abs(wrap_q8(observed - predicted)) <= tolerance)
        slip = 0 if matches or predicted is None or observed is None else self._slip(
            observed - predicted, gap, self._starts_run(slot, observed, ahead, clean, tolerance),
            tolerance)
        if slip:
            slot, predicted, matches = slot + slip, observed, True
        # Against a recent believed angle only the prediction counts; a run of two angles could
        # be two damaged ones that happen to agree.
        run = (not matches and (predicted is None or gap > _FRESH_GAP)
               and self._starts_run(slot, observed, ahead, clean, tolerance))
        self._previous = (slot, observed)
        if matches or run:
            self._believe(slot, observed, ahead if run else None)
            start, replaced = observed, False
        elif predicted is not None:
            start, replaced = predicted, True
        else:
            return Placement(None, None, False, 0)
        if not matches and not run:
            self._misses += 1
            if self._misses >= _RESTART_AFTER:
                # Too long without a believed angle: start over from runs of start angles.
                self._reference = self._sweep = None
        step = None if following is None or not consecutive else (
            (following - start) % FULL_TURN_Q8)
        if step is not None and (abs(step - self._sweep) <= self._tolerance(next_clean)
                                 if self._sweep is not None else 0 < step <= self._max_sweep_q8):
            return Placement(start, step, replaced, slip)
        if next_clean and next_field & 0x8000:
            return Placement(start, None, replaced, slip)   # before a restart: dropped (SDK)
        # The next start angle is damaged or far: sweep as the capsules before.
        return Placement(start, self._sweep, replaced, slip)

    def _in_sequence(self, slot: int, field: int) -> bool:
        """Tell whether a start angle is the predicted one, as a capsule's that passed."""
        predicted, _ = self._predict(slot)
        observed = start_q8(field)
        return (predicted is not None and observed is not None
                and abs(wrap_q8(observed - predicted)) <= self._tolerance(True))

    def _slip(self, beyond_q8: int, gap: int, runs_on: bool, tolerance: float) -> int:
        """
        Tell how many capsules the stream lost unseen, from a start angle ahead of prediction.

        :param beyond_q8: the observed start angle minus the predicted one, 1/256 degree
        :param gap: capsules since the last believed start angle
        :param runs_on: the successor's start angle follows on at the sweep
        :param tolerance: how far the angle may lie from a whole number of sweeps
        :return: capsules lost (negative: counted too many), 0 when it does not look like that
        """
        if not runs_on:
            return 0
        beyond = wrap_q8(beyond_q8)
        lost = round(beyond / self._sweep)
        if lost == 0 or gap + lost < 1 or abs(beyond - lost * self._sweep) > tolerance:
            return 0
        return lost

    def _tolerance(self, clean: bool) -> float:
        """Return how far a start angle may lie from its prediction, 1/256 degree."""
        if not clean or self._sweep is None:
            return _ANGLE_TOLERANCE_Q8
        # A passing checksum makes a damaged angle unlikely: allow for the motor's speed.
        return max(self._sweep / _CLEAN_ANGLE_SHARE, _ANGLE_TOLERANCE_Q8)

    def _predict(self, slot: int) -> tuple:
        """Return the predicted start angle (1/256 degree) and its distance in capsules."""
        if self._reference is None or self._sweep is None:
            return None, None
        gap = slot - self._reference[0]
        if not 0 < gap <= _PREDICTION_REACH:
            return None, None
        return round(self._reference[1] + gap * self._sweep) % FULL_TURN_Q8, gap

    def _starts_run(self, slot: int, observed, ahead, clean: bool, tolerance: float) -> bool:
        """Tell whether a start angle advances to its successor's like the capsules before."""
        if ahead is None or not 0 < ahead <= self._max_sweep_q8:
            return False
        if self._sweep is not None:
            return abs(ahead - self._sweep) <= tolerance
        if self._previous is not None and self._previous[0] == slot - 1 and (
                self._previous[1] is not None):
            # An intact capsule too, where the step behind it is a plausible sweep: a replayed
            # one is intact, and its steps disagree. After a step no sweep makes the capsule
            # before is no evidence: the SDK's rule.
            behind = (observed - self._previous[1]) % FULL_TURN_Q8
            if clean and not 0 < behind <= self._max_sweep_q8:
                return True
            return abs(ahead - behind) <= (max(behind / _CLEAN_ANGLE_SHARE, _ANGLE_TOLERANCE_Q8)
                                           if clean else _ANGLE_TOLERANCE_Q8)
        # At the start of a stream, nothing to compare with: the SDK's rule, for intact capsules.
        return clean

    def _believe(self, slot: int, start: int, run_sweep):
        """Take a start angle as true: it becomes the reference and refines the sweep."""
        self._misses = 0
        if self._reference is not None and self._reference[0] == slot - 1:
            measured = (start - self._reference[1]) % FULL_TURN_Q8
            if self._sweep is None:
                self._sweep = measured if 0 < measured <= self._max_sweep_q8 else None
            elif abs(measured - self._sweep) <= self._sweep / _CLEAN_ANGLE_SHARE:
                self._sweep += (measured - self._sweep) * _SWEEP_WEIGHT
        elif self._sweep is None:
            self._sweep = run_sweep
        self._reference = (slot, start)


def start_q8(field: int):
    """Return a start angle field's angle in 1/256 degree, None when beyond 360 degrees."""
    angle_q6 = field & 0x7FFF
    return angle_q6 << 2 if angle_q6 < FULL_TURN_Q6 else None
