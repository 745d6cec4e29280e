"""The drive's clock under a sped-up (or slowed) replay: ``odocan replay --realtime --speed N``.

The live judges read periods, silences and stalls from bus time against the encoders' 10 ms
cycle (``busfacts.ENC_CYCLE_S``): a silence's periods are the E2E COUNTER's step widened by the
bus time past its lap of 16. A log played N times faster compresses every bus time N-fold (the
receiver stamps frames as it hears them: a udp_multicast or socketcan interface keeps no sender's
time), so a 0.5 s bus-off heard at ``--speed 4`` lasts 12.5 periods, under the COUNTER's lap:
the monitor read the COUNTER's step as 2 periods, not 50, refused the step, took the frames
after it for a counter restart the firmware never made, and blamed a correct firmware
(issue #11: POSE WRONG 1109.8 mm, DISTANCE 237.9 mm; PASS at ``--speed 1``).

``LivePace`` measures the bus's pace from WHEEL_ENCODERS itself, the motor controller's cadence:
the intervals between CRC-right frames one COUNTER step apart (no frame lost between them), in
whichever order they came (``host.judge.pacepairs``: a live bus reordered by ``delay=0.5:20`` was
taken for a replay at ``--speed 0.7``, its times compressed, POSE WRONG on a correct firmware).
It decides on the first ``PACE_INTERVALS``: their mean, and their mean with those over
``SILENCE_PERIODS`` mean periods left out (a silence of 17, 33, ... periods steps the COUNTER by
one too); a bus is live unless both lie outside ``LIVE_BAND`` (no sender's clock is that far
off). A live bus's times are kept as they are, for good. On another, every frame is stamped on
the drive's clock, ``t' = t'_0 + (t - t_0) x pace``, the pace the plain mean's (a receiver that
reads in bursts stamps one-step intervals of 0 and of up to 56 periods at ``--speed 20``: left
out, they ran the pace away to 54), narrowed to the mean of every one-step interval heard from
``NARROWED_AFTER`` on, the map kept continuous. The judges then see the drive as it was
recorded and say what they would say at ``--speed 1``. The frames heard before the pace is
measured (``PACE_INTERVALS`` encoder periods, 0.64 s of a drive) keep their bus times."""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass

import can
from cantools.database.can import Database

from odocan.host.judge.pacepairs import EncoderPairs
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK, ENC_CYCLE_S
from odocan.host.protocol.decode import frame_key
from odocan.host.protocol.e2e import e2e_messages
from odocan.host.protocol.e2e_crc import crc8h2f_p02_one

PACE_INTERVALS = 64  # one-step intervals measured before the pace is decided
SILENCE_PERIODS = 16  # a one-step interval longer than this many periods is a silence (17+)
NARROWED_AFTER = 4 * PACE_INTERVALS  # from then on the pace is the mean of every one-step interval
LIVE_BAND = (0.8, 1.25)  # paces (encoder cycles per bus period) taken as a live bus


@dataclass
class PaceFacts:
    """What the pace decided: None while measuring, 1.0 for a live bus, else the factor."""

    pace: float | None = None
    decided_after_s: float | None = None  # bus seconds from the first encoder frame heard


class LivePace:
    """Bus time to the drive's time (module docstring); ``bus_time`` per frame heard."""

    def __init__(self, db: Database) -> None:
        encoders = next((m for m in db.messages if m.name == "WHEEL_ENCODERS"), None)
        config = None if encoders is None else e2e_messages(db).get(
            frame_key(encoders.frame_id, encoders.is_extended_frame))
        self._id = -1 if encoders is None or encoders.is_extended_frame else encoders.frame_id
        self._data_ids = None if config is None else config.data_ids
        self.facts = PaceFacts(pace=1.0 if self._data_ids is None else None)
        self._pairs = EncoderPairs()  # the CRC-right ones' one-step intervals (pacepairs)
        self._last: tuple[float, int] | None = None  # (bus time, COUNTER) of the last CRC-right
        self._in_order: list[float] = []  # one-step intervals of frames heard in turn
        self._first_s: float | None = None  # the bus time the first CRC-right one was heard
        self._intervals: list[float] = []
        self._origin = (0.0, 0.0)  # (bus time as heard, drive time) the map counts from
        self._sum_s, self._count = 0.0, 0  # the one-step intervals the pace is narrowed by

    @property
    def pace(self) -> float:
        """The factor bus time is multiplied by (1.0 until measured, and on a live bus)."""
        return self.facts.pace or 1.0

    def bus_time(self, t_s: float, can_id: int, data: bytes, extended: bool) -> float:
        """The drive's time of a frame heard at bus time ``t_s`` (its identifier and payload
        measure the pace when it is a WHEEL_ENCODERS frame)."""
        pace = self.facts.pace
        if pace == 1.0:
            return t_s
        if can_id == self._id and not extended and len(data) == 8:
            self._measure(t_s, data)
        origin_t, origin_drive = self._origin
        return origin_drive + (t_s - origin_t) * self.pace

    def stamped(self, msg: can.Message) -> can.Message:
        """``msg`` on the drive's clock: itself when its time is kept, else a copy."""
        t_s = self.bus_time(msg.timestamp, msg.arbitration_id, bytes(msg.data), msg.is_extended_id)
        if t_s == msg.timestamp:
            return msg
        stamped = copy.copy(msg)
        stamped.timestamp = t_s
        return stamped

    def _measure(self, t_s: float, data: bytes) -> None:
        """One encoder frame heard: the one-step intervals it closes (``pacepairs``, in any
        order) measure (or narrow) the pace; while undecided, so does its interval from the
        frame heard just before it when one COUNTER step after it (``_decide``)."""
        assert self._data_ids is not None
        counter = data[1] & ENC_COUNTER_MASK
        if crc8h2f_p02_one(data, self._data_ids[counter]) != data[0]:
            return
        if self._first_s is None:
            self._first_s = t_s
        last, self._last = self._last, (t_s, counter)
        if last is not None and (counter - last[1]) & ENC_COUNTER_MASK == 1 and t_s >= last[0]:
            self._in_order.append(t_s - last[0])
        for interval_s in self._pairs.intervals(t_s, counter, data):
            self._sum_s, self._count = self._sum_s + interval_s, self._count + 1
            if self.facts.pace is None:
                self._intervals.append(interval_s)
                if len(self._intervals) >= PACE_INTERVALS:
                    self._decide(t_s)
            elif self.facts.pace != 1.0 and self._count >= NARROWED_AFTER and self._sum_s > 0:
                self._repace(t_s, ENC_CYCLE_S * self._count / self._sum_s)

    def _decide(self, t_s: float) -> None:
        """The pace from the intervals measured: a live bus's 1.0 unless their mean and their
        mean without silences (``_mean_period_s``) lie outside ``LIVE_BAND``, both for the pairs
        in any order and for the frames heard in order (a live bus with a silence stepping the
        COUNTER by one stays live; a replay heard in bursts has no interval left but its bursts'
        gaps and zeros; a frame held back 15 periods or more, ``delay=0.5:150``, comes one
        COUNTER step ahead of the one furthest ahead, where ``pacepairs`` reads it: pace 1.27,
        the frames heard in order 1.001; on a bus in order both are the same). The pace is then
        the plain mean's of the pairs, which neither a receiver's bursts nor a reorder bias."""
        first_s = t_s if self._first_s is None else self._first_s  # (a log's first at 0.0)
        self.facts.decided_after_s = t_s - first_s
        paces = [_pace_of(sum(self._intervals) / len(self._intervals))]
        for intervals in (self._intervals, self._in_order):
            if intervals:
                paces += [_pace_of(sum(intervals) / len(intervals)),
                          _pace_of(_mean_period_s(intervals))]
        self._intervals, self._in_order = [], []
        if any(LIVE_BAND[0] <= pace <= LIVE_BAND[1] for pace in paces):
            self.facts.pace = 1.0
            return
        self._repace(t_s, paces[0])

    def _repace(self, t_s: float, pace: float) -> None:
        """From bus time ``t_s`` on, the drive's clock runs ``pace`` times the bus's (the map
        stays continuous: it counts from ``t_s``'s drive time). A pace that is no finite
        positive factor (the intervals' mean zero or below: frames stamped alike, or a clock
        going back, which pairs in any order can sum to) is none: still measuring."""
        if not 0.0 < pace < math.inf:
            return
        origin_t, origin_drive = self._origin
        self._origin = (t_s, origin_drive + (t_s - origin_t) * self.pace)
        self.facts.pace = pace

    def said(self, who: str) -> str | None:
        """A line for the watch's end when the drive's clock was not the bus's (else None)."""
        pace = self.facts.pace
        if pace is None or pace == 1.0:
            return None
        return (f"{who}: the bus ran {pace:.3g}x the encoders' {ENC_CYCLE_S * 1e3:g} ms cycle "
                f"(a replay at --speed {pace:.2g}?): judged on the drive's clock, bus time "
                f"x {pace:.4g}")

    def as_dict(self) -> dict[str, float | None]:
        """The pace for the snapshot (None while measuring)."""
        return {"pace": self.facts.pace, "decided_after_s": self.facts.decided_after_s}


def _mean_period_s(intervals_s: list[float]) -> float:
    """The mean one-step interval, those over ``SILENCE_PERIODS`` times the mean left out
    (a silence of 17, 33, ... periods steps the COUNTER by one too), twice narrowed."""
    period_s = sum(intervals_s) / len(intervals_s)
    for _ in range(2):
        kept = [i for i in intervals_s if i <= SILENCE_PERIODS * period_s]
        period_s = sum(kept) / len(kept) if kept else period_s
    return period_s


def _pace_of(period_s: float) -> float:
    """The pace of a bus whose encoder frames come ``period_s`` apart (a zero: infinite)."""
    return ENC_CYCLE_S / period_s if period_s > 0 else math.inf
