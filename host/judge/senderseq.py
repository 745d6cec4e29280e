"""The sender's sequence numbers of a periodic message's frames (bus order) and the frames of it
that waited in the sender's transmit buffer (a burst): shared by the whole-log judge
(``samples.encoder_frames``, ``samples.match_encoder``) and the live one (``livewindow``,
``liveplace``)."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, ENC_COUNTER_MASK

QUEUED_GAP_CYCLES = 0.35  # two sends of one message closer than this waited (``queued_frames``)
BURST_END_CYCLES = 1.5  # a step this long ends a recorder's burst (``burst_laps``)
LATE_SLACK_CYCLES = 2.0  # a frame this much earlier than its neighbours is no stamp's jitter
LAP = ENC_COUNTER_LAP  # 16: the 4-bit COUNTER's lap

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


def sender_seq(counter: IntArray, timestamp_s: FloatArray, cycle_s: float | None,
               holes: npt.NDArray[np.bool_] | None = None) -> IntArray:
    """The sender's sequence numbers of encoder frames (bus order; ``counter``: their E2E
    COUNTER, ``timestamp_s``: bus times): COUNTER steps mod 16, widened by 16 where the time
    stamps say that many more periods passed, unless the frame after the gap came in a burst
    (``queued_frames``) and the gap is no hole of the log (``holes``, per step: the log lost
    the firmware's frames there too, ``pose_skips``; None: none known): a hole's burst is
    numbered by ``burst_laps``. Shared by ``encoder_frames`` and the live judge
    (``host.judge.tracking``), which applies it to its window of recent frames."""
    step = np.diff(counter).astype(np.int64, copy=False)
    step &= ENC_COUNTER_MASK
    if cycle_s is not None and len(step):  # in place: the same operations, fewer temporaries
        gap_periods = np.diff(timestamp_s)
        gap_periods /= cycle_s
        gap_periods -= step  # the sends more than the COUNTER step, 16 a lap (a real number)
        lost_16 = np.floor(gap_periods / LAP + 0.5)  # the lap nearest: an edge 8 periods off,
        np.maximum(0, lost_16, out=lost_16)  # never at half a period (frames late by 0.5)
        lost = lost_16.astype(np.int64)
        lost *= LAP
        # a frame let out in a burst after the gap waited in the sender's buffer: the gap is
        # a busy bus, not lost frames (the COUNTER step is the whole step), but for a step of
        # 0, which E2E takes by the time alone (``host.protocol.e2e_cycles``); and but for a
        # hole of the log, whose burst is the recorder's backlog (``burst_laps``)
        queued = queued_frames(timestamp_s, cycle_s)
        held = queued[1:] & (step != 0)
        in_holes: list[int] = (np.flatnonzero(held & (lost > 0) & holes).tolist()
                               if holes is not None else [])
        lost[held] = 0
        for k in in_holes:
            lost[k] = burst_laps(k, step, queued, timestamp_s, cycle_s)
        step += lost
        late_lone_frames(step, lost, holes, timestamp_s, cycle_s)
    seq: IntArray = np.empty(len(step) + 1, dtype=np.int64)
    seq[0] = 0
    np.cumsum(step, out=seq[1:])
    return seq


def pose_skips(enc_position: IntArray, pose_position: IntArray, pose_counter: IntArray
               ) -> npt.NDArray[np.bool_]:
    """Per step between consecutive encoder frames (``enc_position``: their places in the
    log): whether the log lost pose frames around the later one, a hole of the log. The
    firmware sends a pose (``pose_position``, its E2E COUNTER ``pose_counter``) every other
    period whatever the encoder frames do, so the last pose before the later frame and the
    first after it follow each other (COUNTER + 1) unless the log lost frames of every message
    there: a recorder's kernel buffer dropped a chunk (issue #11, rule 5: the evidence
    recordings of a correct firmware, numbered 16 periods short after such chunks read in a
    burst, FAILed at 0.31 and 0.53 mm). A busy bus (the poses queued, then let out), a stalled
    sender (the firmware went on) or a silent bus (nothing was sent) keeps the poses' COUNTER
    going one by one. (A chunk of 32 k periods brings the poses' COUNTER round: not told.)"""
    if len(pose_position) < 2:
        return np.zeros(max(len(enc_position) - 1, 0), dtype=bool)
    after = np.searchsorted(pose_position, enc_position[1:])
    known = (after > 0) & (after < len(pose_position))
    at = np.minimum(after, len(pose_position) - 1)
    skips: npt.NDArray[np.bool_] = known & (
        ((pose_counter[at] - pose_counter[np.maximum(at - 1, 0)]) & ENC_COUNTER_MASK) != 1)
    return skips


def queued_frames(timestamp_s: FloatArray, cycle_s: float) -> npt.NDArray[np.bool_]:
    """Frames of one periodic sender (in bus order) that waited in its transmit buffer: less
    than ``QUEUED_GAP_CYCLES`` encoder cycles from the one before or after them. A firmware
    sends each pose and twist message at most once per encoder period, so two of them that
    close on the bus were not sent when they were made (a busy bus, e.g. a babbling node of
    higher priority, held them back and then let them out in a burst).

    A frame whose time goes back (a negative gap: it reached the bus after a later one, a frame
    late on the bus, reordered) is not queued by that gap. The band: a burst's frames follow
    each other by one frame's length (about 0.27 ms at 500 kbit/s, 2.7 ms at 50 kbit/s: 0.27
    encoder cycle), while a frame late by half a cycle (a 15 ms ``delay`` of a 20 ms message
    sent 1 ms after a 10 ms slot) lands 0.5 cycle from its neighbour: the edge at 0.35 cycle
    is neither, so no decision hinges on half a cycle (at 0.5, 1 ns of rounding did)."""
    gap_s = np.diff(timestamp_s)
    close = (gap_s >= 0) & (gap_s < QUEUED_GAP_CYCLES * cycle_s)
    queued: npt.NDArray[np.bool_] = (
        np.concatenate(([False], close)) | np.concatenate((close, [False]))
    )
    return queued


def burst_laps(k: int, step: IntArray, queued: npt.NDArray[np.bool_], timestamp_s: FloatArray,
               cycle_s: float) -> int:
    """The sends (16 a lap) lost in the hole of the log (``pose_skips``) before frame ``k + 1``,
    the first of a burst (``queued``). A recorder that stalled reads its kernel buffer at once
    and stamps the backlog as it reads it: its stamps are late, never early. So each frame
    ``b`` of the burst, and the first one after it (on time again, unless another gap comes
    first), gives the laps nearest the periods from frame ``k`` to it less the COUNTER steps
    between (``step``), too many by its own lateness; the fewest of them is the estimate. A
    stall that dropped nothing (the burst holds its periods' frames: the steps catch up with
    the stamps) loses none; one whose buffer dropped a chunk (the burst holds a few periods'
    frames) the chunk's laps. The frame before the hole may be stamped late too (the last
    pass's wake-up): up to 8 periods, as the rounding allows."""
    laps: int | None = None
    made = 0
    for b in range(k + 1, len(timestamp_s)):
        if b > k + 1 and timestamp_s[b] - timestamp_s[b - 1] >= BURST_END_CYCLES * cycle_s:
            break  # the burst ended in another gap: frame b is no time for this one
        made += int(step[b - 1])
        span = float(timestamp_s[b] - timestamp_s[k]) / cycle_s
        est = math.floor((span - made) / LAP + 0.5)
        laps = est if laps is None else min(laps, est)
        if not queued[b]:
            break
    return LAP * max(0, laps or 0)


def late_lone_frames(step: IntArray, lost: IntArray, holes: npt.NDArray[np.bool_] | None,
                     timestamp_s: FloatArray, cycle_s: float) -> None:
    """In place: a lap of ``step`` (``sender_seq``'s; ``lost``: the laps it added) that the
    stamps put at a step only because the frame after it was stamped 8 periods late or more is
    moved to the step after that frame (issue #11, rule 3: a recorder that stamped the frame
    before its chunk 10 periods late had the lap counted at the single step before it, which
    took a gap's allowance there, and a firmware 1 LSB wrong at that step PASSed; the chunk was
    numbered a lap short).

    A recorder, like a bus, stamps late, never early. Let r = stamp / cycle - sequence number:
    frames on time share one level, a late frame lies above it. A frame f after a step that
    took a lap from the stamps (not in a hole of the log, ``pose_skips``, when known) numbered
    so that r(f) lies more than ``LATE_SLACK_CYCLES`` below both r(f - 1) and the least late of
    the 16 frames after f would make every frame around it late by that much and f alone on
    time (the lap before f's stamp: f early). One lap fewer before f and one more after it
    puts f above them instead: late, as the recorder stamped it. A sender's stall (stamps on
    time) leaves f at the level: its lap is kept; so is a lap the frames after f do not take
    (their level 16 below: no second step to carry it)."""
    at = lost[:-1] >= LAP
    if holes is not None:
        at &= ~holes[:-1]
    picks = np.flatnonzero(at)
    if not len(picks):
        return
    seq = np.concatenate(([0], np.cumsum(step)))
    level = timestamp_s / cycle_s - seq
    for i in picks.tolist():
        if i + 2 >= len(level):  # no frame after f: nothing tells
            break
        after = float(np.min(level[i + 2 : i + 2 + LAP]))
        if level[i + 1] < min(float(level[i]), after) - LATE_SLACK_CYCLES:
            step[i] -= LAP
            step[i + 1] += LAP
