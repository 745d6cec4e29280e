"""Receive periods between two frames of one message, from their times (``host.protocol.e2e``'s
time-widened window): rounded for most messages; from the sender's COUNTER step and the ticks a
late frame waited for the messages checked per period (``receive_periods``), with no tie at
half a period."""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from odocan.host.protocol.busfacts import ENC_COUNTER_LAP

# The firmware's tick after the encoder frame's slot, in periods (``receive_periods``).
RECEIVE_LAG_CYCLES = 0.1
COUNTER_MODULO = ENC_COUNTER_LAP  # 16
# How far two frames' receive timestamps may be off each other, in periods (``receive_periods``):
# a live capture (candump on a loaded host, the monitor's own recording) stamps each frame up to a
# few ms late, so 4.5 ms at 100 Hz. A first frame that looks late by no more than this may have
# been on time: timing alone cannot refuse the second (``receive_periods``).
CAPTURE_TOLERANCE_CYCLES = 0.45


def periods_between(
    dt_s: npt.NDArray[np.float64], cycle_s: float | None, min_periods: int = 1
) -> npt.NDArray[np.int64]:
    """Receive periods that a frame ``dt_s`` after the previous one closes: ``round(dt /
    cycle)``, at least ``min_periods`` (0: a second frame in one period widens no window); 1
    each without a cycle time."""
    if cycle_s is None:
        return np.ones(dt_s.shape, dtype=np.int64)
    quotient = np.divide(dt_s, cycle_s, out=np.empty(np.shape(dt_s), dtype=np.float64))
    np.rint(quotient, out=quotient)  # in place: one temporary, not three
    np.maximum(quotient, min_periods, out=quotient)
    return quotient.astype(np.int64)


def period_count(dt_s: float, cycle_s: float | None, min_periods: int = 1) -> int:
    """``periods_between`` for one frame, without numpy (the live check runs it per frame):
    the same round-half-even of the same float64 quotient; a NaN or infinite gap counts 1."""
    if cycle_s is None or not math.isfinite(dt_s):
        return 1
    return max(min_periods, round(dt_s / cycle_s))


def receive_periods(
    dt_s: npt.NDArray[np.float64], step: npt.NDArray[np.int64], cycle_s: float,
    tolerance_cycles: float = CAPTURE_TOLERANCE_CYCLES,
) -> npt.NDArray[np.int64]:
    """Receive periods (the firmware's ticks, >= 0) between two frames of one periodic sender,
    ``dt_s`` apart on the bus, the second ``step`` sends after the first (their COUNTER
    difference mod 16; both CRCs right, so both COUNTERs are the sender's).

    The rule, for one frame of the pair on time (on the sender's grid) and the other late by
    ``L`` periods (held back on the bus, e.g. a ``delay`` fault: reordered): ``x = dt / cycle``
    is the sender's step ``s`` plus ``e = +L`` (the second frame late) or ``e = -L`` (the
    first). ``s`` is the integer congruent to ``step`` mod 16 nearest ``x`` (a lateness below
    8 periods). The receiver takes a frame at its first tick no earlier than the frame, ticking
    ``RECEIVE_LAG_CYCLES`` after the sender's slots (the rig's board runs 1 ms = 0.1 period
    after the motor controller sends, ``sim.rig``), so a frame late by ``L`` waits
    ``ceil(L - lag)`` ticks more (none when ``L <= lag``): the periods are ``s`` plus that for a
    late second frame, ``s`` minus it for a late first one, at least 0.

    No tie at half a period: ``e = +-0.5`` (a 15 ms delay of a 10 ms message) gives
    ``s +- 1`` whichever side of 0.5 the timestamps' rounding puts it (``ceil(0.5 +- 1e-6 -
    0.1) = 1``), where ``round(x)`` (half to even) flipped between a ``.log`` and a ``.blf``
    of the same drive. The one edge left is a frame late by exactly the lag: the receiver's own
    tick, an edge the firmware has too (it takes a frame that ended exactly at its tick, not
    one that ended later). Both frames on time: ``|e|`` is bus jitter, below the lag: ``s``,
    what ``round(x)`` gives.

    Timestamps are trusted to ``tolerance_cycles`` only (``CAPTURE_TOLERANCE_CYCLES``; a
    capture stamps each frame up to a few ms late, each its own). Where the first frame looks
    late (``e < 0``), it is taken late by ``|e| - tolerance_cycles`` only (on time within the
    tolerance): the window is then never narrower than the firmware's, so the host never
    refuses an encoder frame the firmware took (a pose naming it would be paired with the frame
    16 periods before: the trial's 363 mrad on a correct firmware). What this allows is
    bounded: one period more than the exact-time rule, for a pair whose first frame looks late
    by up to the tolerance; a frame the firmware refused and the host took costs the reference
    only the split of one arc in two. Exact stamps on the firmware's grid (``e`` a whole
    number) give what the exact rule gives: ``ceil(k - tolerance - lag) = k``. Where the second
    frame looks late (``e > 0``), the exact rule stands: a stamp late by jitter only adds
    periods (a wider window), and a frame truly late, seen less late, is the sender's next
    COUNTER, within the window either way. Edges: ``|e|`` = ``lag + tolerance + k`` (5.5 ms
    at 100 Hz), between the rig's whole-ms frame times."""
    x = dt_s / cycle_s
    s = step + COUNTER_MODULO * np.floor((x - step + COUNTER_MODULO // 2) / COUNTER_MODULO)
    e = x - s
    np.copyto(e, np.minimum(e + tolerance_cycles, 0.0), where=e < 0)
    late = np.ceil(np.abs(e) - RECEIVE_LAG_CYCLES)
    np.maximum(late, 0.0, out=late)
    periods = s + np.sign(e) * late
    np.maximum(periods, 0.0, out=periods)
    result: npt.NDArray[np.int64] = periods.astype(np.int64)
    return result


def receive_period_count(dt_s: float, step: int, cycle_s: float,
                         tolerance_cycles: float = CAPTURE_TOLERANCE_CYCLES) -> int:
    """``receive_periods`` for one pair of frames, without numpy (the live check), the same
    float64 operations; a NaN or infinite gap counts 1."""
    if not math.isfinite(dt_s):
        return 1
    x = dt_s / cycle_s
    s = step + COUNTER_MODULO * math.floor((x - step + COUNTER_MODULO // 2) / COUNTER_MODULO)
    e = x - s
    if e < 0:
        e = min(e + tolerance_cycles, 0.0)
    late = max(math.ceil(abs(e) - RECEIVE_LAG_CYCLES), 0)
    return max(int(s + (late if e > 0 else -late if e < 0 else 0)), 0)


def frame_periods(
    timestamp_s: npt.NDArray[np.float64], counter: npt.NDArray[np.int64],
    crc_ok: npt.NDArray[np.bool_], cycle_s: float | None, min_periods: int,
) -> npt.NDArray[np.int64]:
    """The periods each frame of one message (bus order) adds to the window: ``periods_between``,
    and ``receive_periods`` for the messages checked per period (``min_periods`` 0) where the
    frame and the one before it have a right CRC."""
    dt = np.diff(timestamp_s, prepend=timestamp_s[:1])
    periods = periods_between(dt, cycle_s, min_periods)
    if min_periods == 0 and cycle_s is not None and len(timestamp_s) > 1:
        both = np.flatnonzero(crc_ok[1:] & crc_ok[:-1]) + 1
        step = (counter[both] - counter[both - 1]) & (COUNTER_MODULO - 1)
        periods[both] = receive_periods(dt[both], step, cycle_s)
    return periods
