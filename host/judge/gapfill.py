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
``gapbound`` allowance); a frame is held back fewer than 8 periods (``e2e_periods``' rule), so
its sequence number is the one of its COUNTER in (est - 8, est + 1], est the periods since the
last accepted frame before it on the bus; two frames of one number must agree (else unknown);
the firmware takes its frames in sequence order (E2E: never one behind one it took).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.breaks import merge_allowance_m
from odocan.host.judge.gapbound import gap_allowance_of_counts, period_bounds
from odocan.host.judge.reference import Geometry, SpeedBound, wrap_delta
from odocan.host.judge.samples import Encoders, IntArray
from odocan.host.protocol.decode import BulkDecoder, DecodeError
from odocan.host.protocol.e2e import crc8h2f_p02, e2e_messages

COUNTER_MODULO = 16
MAX_LATE_PERIODS = 8  # a frame held back fewer periods than this (half a COUNTER cycle)
Counts = tuple[int, int]  # (left, right) wire counts


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
        found = [self.counts.get(s) for s in range(seq_before + 1, seq_before + periods)]
        return None if any(c is None for c in found) else found  # type: ignore[return-value]


def late_seq(counter: IntArray, sent_s: np.ndarray, anchor_seq: IntArray, anchor_s: np.ndarray,
             cycle_s: float) -> IntArray:
    """Sender sequence numbers of refused frames (COUNTER, bus time) after accepted frames
    (sequence number, bus time): the number of their COUNTER in (est - 8, est + 1]; -1 where
    it lies further back (held back too long to be placed)."""
    est = anchor_seq + np.floor((sent_s - anchor_s) / cycle_s + 0.5).astype(np.int64)
    top = est + 1  # the highest number allowed
    seq: IntArray = top - ((top - counter) % COUNTER_MODULO)
    return np.where(seq > est - MAX_LATE_PERIODS, seq, -1)


def late_in_chunk(chunk: FrameArrays, decoder: BulkDecoder, enc: Encoders, offset: int,
                  last: tuple[int, float] | None) -> tuple[IntArray, IntArray, IntArray]:
    """(sequence numbers, left, right) of the chunk's encoder frames the host refused whose CRC
    holds (``enc``: the accepted ones, ``index`` in the log; the chunk starts at ``offset``;
    ``last``: the last accepted frame before it, sequence number and bus time)."""
    empty = np.zeros(0, dtype=np.int64)
    try:
        rows = decoder.select(chunk, "WHEEL_ENCODERS")
    except (DecodeError, KeyError):
        return empty, empty, empty
    refused = ~np.isin(rows + offset, enc.index)
    if not refused.any() or enc.cycle_s is None:
        return empty, empty, empty
    decoded = decoder.decode(chunk, "WHEEL_ENCODERS")
    pick = np.flatnonzero(refused & _crc_holds(chunk, decoder, rows))
    k = np.searchsorted(enc.index, rows[pick] + offset) - 1
    if last is None:  # none accepted before: nothing to place them after
        pick, k = pick[k >= 0], k[k >= 0]
    seq_a = np.where(k >= 0, enc.seq[np.maximum(k, 0)] if len(enc.seq) else 0,
                     last[0] if last else 0)
    time_a = np.where(k >= 0, enc.timestamp_s[np.maximum(k, 0)] if len(enc.seq) else 0.0,
                      last[1] if last else 0.0)
    seq = late_seq(decoded["COUNTER"][pick].astype(np.int64), decoded["timestamp_s"][pick],
                   seq_a.astype(np.int64), time_a, enc.cycle_s)
    return (seq, decoded["LEFT_COUNT"][pick].astype(np.int64),
            decoded["RIGHT_COUNT"][pick].astype(np.int64))


def _crc_holds(chunk: FrameArrays, decoder: BulkDecoder, rows: IntArray
               ) -> npt.NDArray[np.bool_]:
    message = decoder.message("WHEEL_ENCODERS")
    config = e2e_messages(decoder.db).get(message.frame_id)
    if config is None or config.data_ids is None:
        return np.zeros(len(rows), dtype=bool)  # unprotected: a frame refused is not the sender's
    data = chunk.data[rows]
    ids = np.array(config.data_ids, dtype=np.uint8)[data[:, 1] & 0xF]
    good: npt.NDArray[np.bool_] = crc8h2f_p02(data, ids) == data[:, 0]
    return good


def gap_or_fill_allowance(
    filled: list[Counts] | None, before: Counts, after: Counts, periods: int,
    geometry: Geometry, bits: int, integrator: str, max_wheel_speed_mm_s: SpeedBound,
) -> float:
    """A gap's allowance (m): ``gapbound``'s, or twice the merge allowance over its frames when
    the log fills it (``filled``: the counts of every frame it lacks) with plausible steps."""
    if filled is not None:
        left = np.array([before[0], *(c[0] for c in filled), after[0]], dtype=np.int64)
        right = np.array([before[1], *(c[1] for c in filled), after[1]], dtype=np.int64)
        if _plausible(left, right, geometry, bits, max_wheel_speed_mm_s):
            return 2.0 * merge_allowance_m(left, right, geometry, bits, integrator)
    return gap_allowance_of_counts(before, after, periods, geometry, bits, integrator,
                                   max_wheel_speed_mm_s)


def _plausible(left: IntArray, right: IntArray, geometry: Geometry, bits: int,
               max_wheel_speed_mm_s: SpeedBound) -> bool:
    """Whether every one-period step is within the firmware's plausibility bound (none known:
    no)."""
    speed_mm_s = geometry.speed_bound_mm_s(max_wheel_speed_mm_s)
    if speed_mm_s is None:
        return False
    bound_left, bound_right = period_bounds(geometry, speed_mm_s)
    d_left = np.abs(wrap_delta(np.diff(left), bits))
    d_right = np.abs(wrap_delta(np.diff(right), bits))
    return bool(np.all(d_left <= bound_left) and np.all(d_right <= bound_right))


def gap_allowance_at(
    enc: Encoders, b: int, filled: list[Counts] | None, geometry: Geometry, bits: int,
    integrator: str, max_wheel_speed_mm_s: SpeedBound,
) -> float:
    """``gap_or_fill_allowance`` of the gap into accepted encoder frame ``b`` of ``enc``."""
    return gap_or_fill_allowance(
        filled, (int(enc.left[b - 1]), int(enc.right[b - 1])),
        (int(enc.left[b]), int(enc.right[b])), int(enc.seq[b] - enc.seq[b - 1]), geometry, bits,
        integrator, max_wheel_speed_mm_s)
