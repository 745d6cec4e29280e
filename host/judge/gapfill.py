"""Gaps of the accepted encoder frames that the log fills itself (issue #11, rule 5: a PASS must
never hide a wrong pose): the frames a ``delay`` fault held back on the bus, refused by the
host's E2E check (WRONG_SEQUENCE, REPEATED) because a later frame came first.

``host.judge.gapbound`` bounds a gap of the log as if its frames were unknown: the worst any
split of the gap's travel within the plausibility bound can do (0.4 to 4.9 m summed over a
10 to 20 s drive on a 1 cm wheelbase with frames reordered, where a firmware adding 1 cm at
every step it took after a lost frame passed). But a frame held back is in the log: its CRC
holds, so its wire counts are the sender's, and its COUNTER with its bus time gives its place
in the sender's sequence. When every frame a gap lacks is such a frame (the gap "filled"), the
sender's counts at every period of the gap are known, and whatever the firmware took of them
(all but the late ones, as the host; or a late one and not its successor, had its E2E window
been narrower), its steps are the fine path's merged in runs over frames of known counts:

    |fw - ref| <= |fw - fine| + |ref - fine| <= 2 * breaks.merge_allowance_m(frames b-1 .. b)

(the fine path over the gap's frames; ``merge_allowance_m`` is the largest sum of run errors
over any runs merged, the reference's one merged step among them). Premises, as everywhere in
the judge: a frame whose CRC holds is the sender's (a forgery is ``samples``' twins' business:
a filled frame must also be a plausible step from its neighbours, else the gap keeps its
``gapbound`` allowance); a frame is held back at most 15 periods (``MAX_LATE_PERIODS``) and
never sent early, so its sequence number is the one of its COUNTER in [est - 15, est], est
its periods on the sender's grid: counted from the least late of the last ``ANCHOR_FRAMES``
accepted frames before it on the bus (time - sequence number * cycle the least); two frames of
one number must agree (else unknown); the firmware takes its frames in sequence order (E2E:
never one behind one it took).

One rule covers the firmware's E2E lock-out too (seed 305, frames held 17..40 ms): after taking
a late frame its window restarts while the COUNTER runs one ahead, so it refuses the on-time
frames that follow (delta = window + 1) until the COUNTER comes round, up to 16 periods. Those
frames are not held back: they are on the bus, CRC good, and the host's copy of the E2E check
refuses them as the firmware does, so the gap is filled like one of held-back frames: the
firmware's step over it is the merge of frames of known counts, never a split of the gap's
travel. Placing them from the last accepted frame (the late one: 2 periods late at 20 ms) put
their COUNTER 16 periods back, out of (est - 8, est + 1], and the gap kept ``gapbound``'s
worst case (135 mm on kobuki, seed 305, ``delay=0.1:20``, 10 s: a firmware adding 1 mm of X
after each lock-out passed; ``tests/test_lockout_fill``). Counted from the least late accepted
frame (late by L periods, 0 <= L < 8), est = s + (d - L) for a frame of number s late by d
periods (0 <= d < 8), within a rounding: when L <= d + 1 (always when one of the last 64
accepted frames was on time) s is in (est - 15, est + 1] and is found when d - L < 15 (a frame
held back 15 periods or more is beyond the rule's premise); otherwise s lies above est + 1,
so the frame is left unplaced and its gap keeps
``gapbound``'s allowance: a frame is never given a wrong number. The live judge applies the
same rule frame by frame (``host.judge.livefill``).

The bound was 8 periods (half a COUNTER cycle); a ``delay`` of 100 ms on a 10 ms encoder period
(10 periods) then left every held-back frame unplaced, its gap kept ``gapbound``'s allowance,
and that absorbed a pose 10 mm off (seed 703, ``delay=0.5:100``: PASSed); 15 (twice the merge
error's 8, one lap less one) places frames held back up to 14 periods behind the least late
anchor (issue #11).

At most 15 (pmir seed 4, ``delay=0.5:150``, 10 s: X raised 10 mm from 5.0 s PASSed both
analyses). A frame held back 150 ms is heard with the on-time frame of the number before it,
its COUNTER one on: E2E takes it as the next frame (``lap_less_one``), a period before the
sender's grid, and as the least late anchor it numbered every refused frame one ahead; the
window (est - 15, est + 1] then put frames held 15 periods a lap ahead (482, 483, heard 4.98,
4.99 s, as 498, 499): the gap before encoder frame 271 kept ``gapbound``'s 12.35 mm, the one
before 273 was filled with counts 16 periods old (3.18 mm), and the placement at 273 took the
9.94 mm within both. Such frames are no anchor now (nor any frame less late than one of them),
and the window is [est - 15, est]: a frame is never sent early, and the least late anchor is
on time within rounding (the +1 once allowed anchors up to 1.5 periods late). The live judge
(``livefill``) keeps the old rule: the same change there moved its error on that correct drive
from 2.5 mm to 17.9 mm beyond its allowance (both FAIL it; not traced).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt
from numpy.lib.stride_tricks import sliding_window_view

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.breaks import merge_allowance_m
from odocan.host.judge.gapbound import gap_allowance_of_counts, period_bounds
from odocan.host.judge.reference import Geometry, SpeedBound, wrap_delta
from odocan.host.judge.samples import Encoders, IntArray
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e_rows import crc_right

COUNTER_MODULO = ENC_COUNTER_LAP  # 16
MAX_LATE_PERIODS = 15  # a frame held back at most this many periods (one COUNTER cycle less
# one; was "fewer than": ``delay=...:150`` holds frames exactly 15 periods, ``lap_less_one``)
ANCHOR_FRAMES = 64  # accepted frames an anchor is chosen among (the least late on the grid)
Counts = tuple[int, int]  # (left, right) wire counts
# accepted frames: sequence numbers, bus times, COUNTERs
Anchors = tuple[IntArray, npt.NDArray[np.float64], IntArray]


@dataclass
class LateFrames:
    """The encoder frames the host refused whose CRC holds, by sender sequence number: their
    wire counts (None: two frames of that number disagreed)."""

    counts: dict[int, Counts | None] = field(default_factory=dict)

    def add(self, seq: IntArray, left: IntArray, right: IntArray) -> None:
        """Frames refused, their CRC right: sequence numbers (-1: not placed), counts."""
        for s, a, c in zip(seq.tolist(), left.tolist(), right.tolist(), strict=True):
            if s < 0:
                continue
            known = self.counts.get(s, (a, c))
            self.counts[s] = (a, c) if known == (a, c) else None

    def fill(self, seq_before: int, periods: int) -> list[Counts] | None:
        """The counts of the frames a gap of ``periods`` after sender frame ``seq_before``
        lacks, when the log holds every one of them (refused); else None."""
        return filled(self.counts, seq_before, periods)

    def known(self, seq_before: int, periods: int) -> list[tuple[int, Counts]] | None:
        """The frames of a gap of ``periods`` after sender frame ``seq_before`` the log holds
        (refused), as (periods after the frame before the gap, counts), those it lacks left out;
        None when two frames of one number disagreed (``gapreceived``)."""
        return held(self.counts, seq_before, periods)


def _numbers_in(counts: dict[int, Counts | None], first: int, end: int) -> list[int]:
    """The numbers in [first, end) that ``counts`` holds, in order: by the shorter of the range
    and the dict (a gap's periods come from its stamps, unbounded: a recorder paused a day, a
    stamp glitched; the dict holds frames of the log)."""
    if end - first <= len(counts):
        return [s for s in range(first, end) if s in counts]
    return sorted(s for s in counts if first <= s < end)


def filled(counts: dict[int, Counts | None], seq_before: int, periods: int
           ) -> list[Counts] | None:
    """``LateFrames.fill`` over ``counts`` (the live judge's too, ``livefill``): None at once
    when the gap lacks more frames than ``counts`` holds."""
    if periods - 1 > len(counts):
        return None
    found = [counts.get(s) for s in range(seq_before + 1, seq_before + periods)]
    return None if any(c is None for c in found) else found  # type: ignore[return-value]


def held(counts: dict[int, Counts | None], seq_before: int, periods: int
         ) -> list[tuple[int, Counts]] | None:
    """``LateFrames.known`` over ``counts`` (the live judge's too, ``livefill``)."""
    found = [(s - seq_before, counts[s])
             for s in _numbers_in(counts, seq_before + 1, seq_before + periods)]
    if any(c is None for _, c in found):
        return None
    return found  # type: ignore[return-value]


def late_seq(counter: IntArray, sent_s: np.ndarray, anchor: Anchors, cycle_s: float) -> IntArray:
    """Sender sequence numbers of refused frames (COUNTER, bus time) after accepted frames
    (``anchor``: sequence number, bus time, COUNTER; a number is its COUNTER's residue shifted
    as the anchor's, the first accepted frame being number 0 whatever its COUNTER): the number
    of their COUNTER in [est - MAX_LATE_PERIODS, est]; -1
    where it lies further back (held back too long
    to be placed)."""
    anchor_seq, anchor_s, anchor_counter = anchor
    est = anchor_seq + np.floor((sent_s - anchor_s) / cycle_s + 0.5).astype(np.int64)
    top = est  # the highest number allowed: never sent early (module docstring, "At most 15")
    seq: IntArray = top - ((top - anchor_seq - counter + anchor_counter) % COUNTER_MODULO)
    return np.where(seq >= est - MAX_LATE_PERIODS, seq, -1)


def late_in_chunk(chunk: FrameArrays, decoder: BulkDecoder, enc: Encoders, offset: int,
                  prior: Anchors) -> tuple[IntArray, IntArray, IntArray]:
    """(sequence numbers, left, right) of the chunk's encoder frames the host refused whose CRC
    holds (``enc``: the accepted ones, ``index`` in the log; the chunk starts at ``offset``;
    ``prior``: the last accepted frames before it, ``recent_anchors``)."""
    empty = np.zeros(0, dtype=np.int64)
    try:
        rows = decoder.select(chunk, "WHEEL_ENCODERS")
    except (DecodeError, KeyError):
        return empty, empty, empty
    refused = ~np.isin(rows + offset, enc.index)
    if not refused.any() or enc.cycle_s is None:
        return empty, empty, empty
    decoded = decoder.decode(chunk, "WHEEL_ENCODERS")
    pick = np.flatnonzero(refused & crc_holds(chunk, decoder, rows))
    k = np.searchsorted(enc.index, rows[pick] + offset) - 1 + len(prior[0])
    pick, k = pick[k >= 0], k[k >= 0]  # none accepted before: nothing to place them after
    seq_a, time_a, counter_a = on_time_anchors(recent_anchors(prior, enc, None), enc.cycle_s)
    seq = late_seq(decoded["COUNTER"][pick].astype(np.int64), decoded["timestamp_s"][pick],
                   (seq_a[k], time_a[k], counter_a[k]), enc.cycle_s)
    return (seq, decoded["LEFT_COUNT"][pick].astype(np.int64),
            decoded["RIGHT_COUNT"][pick].astype(np.int64))


def on_time_anchors(frames: Anchors, cycle_s: float) -> Anchors:
    """Per accepted frame (sequence number, bus time, COUNTER): the least late on the sender's
    grid (the least time - number * cycle) of it and the ``ANCHOR_FRAMES`` - 1 before it, its
    number in the frame's numbering (``lapped_numbers``: a lap the host's numbering gained
    between them added). A frame ``lap_less_one`` flags is no anchor, nor any in its window
    less than half a period later than it on the grid (all of them: the window kept whole)."""
    seq, time_s, counter = frames
    if len(seq) == 0:
        return frames
    laps = lapped_numbers(seq, time_s, cycle_s)
    late_s = time_s - (seq - laps) * cycle_s
    flagged = np.where(lap_less_one(seq - laps, time_s, counter, cycle_s),
                       late_s + 0.5 * cycle_s, -np.inf)
    suspect = np.concatenate((np.full(ANCHOR_FRAMES - 1, -np.inf), flagged))
    below = sliding_window_view(suspect, ANCHOR_FRAMES).max(axis=1)  # per window
    padded = np.concatenate((np.full(ANCHOR_FRAMES - 1, np.inf), late_s))
    windows = sliding_window_view(padded, ANCHOR_FRAMES)
    kept = np.where(windows < below[:, None], np.inf, windows)
    kept = np.where(np.isinf(kept.min(axis=1))[:, None], windows, kept)  # none left: all
    best = np.argmin(kept, axis=1) + np.arange(len(seq)) - (ANCHOR_FRAMES - 1)
    return seq[best] + laps - laps[best], time_s[best], counter[best]


def lap_less_one(seq: IntArray, time_s: npt.NDArray[np.float64], counter: IntArray,
                 cycle_s: float) -> npt.NDArray[np.bool_]:
    """Per accepted frame: whether it may be a frame held back 15 periods (a COUNTER lap less
    one) that the E2E check took as the next one (issue #11, pmir seed 4, ``delay=0.5:150``):
    its COUNTER one on from the accepted frame before it, heard less than half a period after
    that one, it sits a period before that frame's place on the sender's grid, so as the least
    late anchor it numbered every refused frame one period ahead (a frame held back 15 periods
    a lap ahead, its counts 16 periods old filling the wrong gap). Such a frame is no anchor;
    an on-time frame heard right after one held back half a period or more is left out with
    it (another of the ``ANCHOR_FRAMES`` anchors the grid). The previous frame only: the
    streamed judge knows no later one."""
    out = np.zeros(len(seq), dtype=bool)
    if len(seq) > 1:
        early = np.diff(time_s) < 0.5 * cycle_s
        one_on = (np.diff(counter) % COUNTER_MODULO == 1) & (np.diff(seq) == 1)
        out[1:] = early & one_on
    return out


def lapped_numbers(seq: IntArray, time_s: npt.NDArray[np.float64], cycle_s: float) -> IntArray:
    """Per accepted frame: the numbers (16 a lap) the host's numbering gained over the sender's
    since the first (issue #11, rule 5: pmir square 645, ``busoff=2.7:0.2,stall=4.7:0.3,
    delay=0.3:55``). After a stall the host (and the firmware) took COUNTER 15, held back 55 ms,
    after COUNTER 4, sent 5 periods after it: a step of 11, so every number from there on ran
    a lap ahead of the sender's, and the frames that followed on the bus (all accepted ones held
    back, the on-time ones refused) made the held ones the least late. Numbered from them, the
    refused on-time frames' numbers lay a lap behind the host's (4.5 periods after an anchor
    5.5 late), the gaps they fill lacked them, and a pose 10 mm off from 5.3 s PASSed within
    ``gapbound``'s allowance.

    A frame is never sent early: a frame whose place on the grid (time - number * cycle) lies
    more than half a lap (8 periods) before the least late of the ``ANCHOR_FRAMES`` before it
    was numbered ahead of the sender, by the laps nearest (the premise of ``late_seq``: one of
    those frames was on time, and none is held back half a lap or more)."""
    late = time_s / cycle_s - seq
    laps = np.zeros(len(seq), dtype=np.int64)
    start = 1
    while start < len(seq):
        adj = late[start - min(start, ANCHOR_FRAMES):] + laps[start - min(start, ANCHOR_FRAMES):]
        window = min(start, ANCHOR_FRAMES)
        padded = np.concatenate((np.full(ANCHOR_FRAMES - window, np.inf), adj))
        before = sliding_window_view(padded[:-1], ANCHOR_FRAMES).min(axis=1)
        ahead = np.flatnonzero(adj[window:] < before - COUNTER_MODULO / 2)
        if len(ahead) == 0:
            break
        k = int(ahead[0])
        gained = int(np.floor((before[k] - adj[window + k]) / COUNTER_MODULO + 0.5))
        start += k
        laps[start:] += gained * COUNTER_MODULO
        start += 1
    return laps


def recent_anchors(prior: Anchors, enc: Encoders, kept: int | None = ANCHOR_FRAMES) -> Anchors:
    """The last ``kept`` (None: all) accepted frames of ``prior`` then ``enc``."""
    start = -kept if kept else 0
    return (np.concatenate((prior[0], enc.seq)).astype(np.int64)[start:],
            np.concatenate((prior[1], enc.timestamp_s)).astype(np.float64)[start:],
            np.concatenate((prior[2], enc.counter)).astype(np.int64)[start:])


NO_ANCHORS: Anchors = (np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.float64),
                       np.zeros(0, dtype=np.int64))


def crc_holds(chunk: FrameArrays, decoder: BulkDecoder, rows: IntArray,
              name: str = "WHEEL_ENCODERS") -> npt.NDArray[np.bool_]:
    """Which frames ``rows`` (of message ``name``) have a right Profile 2 CRC: the sender's,
    whatever the host's E2E window said of their COUNTER (False: unprotected)."""
    return crc_right(chunk, decoder, rows, name, unprotected=False)  # refused: not the sender's


def gap_or_fill_allowance(
    filled: list[Counts] | None, before: Counts, after: Counts, periods: int,
    geometry: Geometry, bits: int, integrator: str, max_wheel_speed_mm_s: SpeedBound,
) -> float:
    """A gap's allowance (m): ``gapbound``'s, or twice the merge allowance over its frames when
    the log fills it (``filled``: the counts of every frame it lacks) with plausible steps."""
    if filled is not None:
        left = np.array([before[0], *(c[0] for c in filled), after[0]], dtype=np.int64)
        right = np.array([before[1], *(c[1] for c in filled), after[1]], dtype=np.int64)
        allowance = known_counts_allowance_m(left, right, geometry, bits, integrator,
                                             max_wheel_speed_mm_s)
        if allowance is not None:
            return allowance
    return gap_allowance_of_counts(before, after, periods, geometry, bits, integrator,
                                   max_wheel_speed_mm_s)


def known_counts_allowance_m(left: IntArray, right: IntArray, geometry: Geometry, bits: int,
                             integrator: str, max_wheel_speed_mm_s: SpeedBound) -> float | None:
    """Twice the merge allowance (m) over frames of known counts, one a period (``left``,
    ``right``: the firmware and the reference each took a subset of them in sequence order, so
    each is within the merge allowance of the fine path); None when a step is implausible
    (module docstring: then a frame may be a forgery)."""
    if not _plausible(left, right, geometry, bits, max_wheel_speed_mm_s):
        return None
    return 2.0 * merge_allowance_m(left, right, geometry, bits, integrator)


def _plausible(left: IntArray, right: IntArray, geometry: Geometry, bits: int,
               max_wheel_speed_mm_s: SpeedBound) -> bool:
    """Whether every one-period step is within the firmware's plausibility bound (none known:
    no)."""
    return plausible_steps(left, right, np.ones(len(left) - 1, dtype=np.int64), geometry, bits,
                           max_wheel_speed_mm_s)


def plausible_steps(left: IntArray, right: IntArray, periods: IntArray, geometry: Geometry,
                    bits: int, max_wheel_speed_mm_s: SpeedBound) -> bool:
    """Whether every step (of ``periods`` encoder periods each) is within the firmware's
    plausibility bound over its periods (none known: no)."""
    speed_mm_s = geometry.speed_bound_mm_s(max_wheel_speed_mm_s)
    if speed_mm_s is None:
        return False
    bound_left, bound_right = period_bounds(geometry, speed_mm_s)
    d_left = np.abs(wrap_delta(np.diff(left), bits))
    d_right = np.abs(wrap_delta(np.diff(right), bits))
    return bool(np.all(d_left <= bound_left * periods) and np.all(d_right <= bound_right * periods))


def gap_allowance_at(
    enc: Encoders, b: int, filled: list[Counts] | None, geometry: Geometry, bits: int,
    integrator: str, max_wheel_speed_mm_s: SpeedBound,
) -> float:
    """``gap_or_fill_allowance`` of the gap into accepted encoder frame ``b`` of ``enc``."""
    return gap_or_fill_allowance(
        filled, (int(enc.left[b - 1]), int(enc.right[b - 1])),
        (int(enc.left[b]), int(enc.right[b])), int(enc.seq[b] - enc.seq[b - 1]), geometry, bits,
        integrator, max_wheel_speed_mm_s)
