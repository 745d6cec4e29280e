"""The sender's sequence numbers of a periodic message's frames (bus order) and the frames of it
that waited in the sender's transmit buffer (a burst): shared by the whole-log judge
(``samples.encoder_frames``, ``samples.match_encoder``) and the live one (``livewindow``,
``liveplace``)."""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

QUEUED_GAP_CYCLES = 0.35  # two sends of one message closer than this waited (``queued_frames``)

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.int64]


def sender_seq(counter: IntArray, timestamp_s: FloatArray, cycle_s: float | None) -> IntArray:
    """The sender's sequence numbers of encoder frames (bus order; ``counter``: their E2E
    COUNTER, ``timestamp_s``: bus times): COUNTER steps mod 16, widened by 16 where the time
    stamps say that many more periods passed, unless the frame after the gap came in a burst
    (``queued_frames``). Shared by ``encoder_frames`` and the live judge
    (``host.judge.tracking``), which applies it to its window of recent frames."""
    step = np.diff(counter).astype(np.int64, copy=False)
    step &= 0xF
    if cycle_s is not None and len(step):  # in place: the same operations, fewer temporaries
        gap_periods = np.diff(timestamp_s)
        gap_periods /= cycle_s
        gap_periods -= step  # the sends more than the COUNTER step, 16 a lap (a real number)
        lost_16 = np.floor(gap_periods / 16 + 0.5)  # the lap nearest: an edge 8 periods off,
        np.maximum(0, lost_16, out=lost_16)  # never at half a period (frames late by 0.5)
        lost = lost_16.astype(np.int64)
        lost *= 16
        # a frame let out in a burst after the gap waited in the sender's buffer: the gap is
        # a busy bus, not lost frames (the COUNTER step is the whole step), but for a step of
        # 0, which E2E takes by the time alone (``host.protocol.e2e_cycles``)
        lost[queued_frames(timestamp_s, cycle_s)[1:] & (step != 0)] = 0
        step += lost
    seq: IntArray = np.empty(len(step) + 1, dtype=np.int64)
    seq[0] = 0
    np.cumsum(step, out=seq[1:])
    return seq


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
