"""Pose frames that name an encoder frame not yet sent: a firmware defect (issue #11: a PASS
must never hide a wrong pose). One rule for every judge: ``analyze`` whole and streamed
(``AheadScan``, fed the log at once or chunk by chunk), the monitor and the bridge
(``host.judge.liveahead``, fed frame by frame).

A pose frame's ENC_COUNTER names the latest encoder frame the firmware took, so that frame was
sent before the pose. ``samples.match_encoder`` resolves the name against the latest accepted
encoder frame before the pose (-8..+7 frames from it) and leaves the pose out when the frame
resolved comes later in the log: an outside trial raised X 10 mm in poses 0-489 of a square
drive and set their ENC_COUNTER one on; every raised pose was left out and ``analyze`` PASSed
on the 10 left ("judged 10 of 500"), as did the streamed judge and the live monitor.

A forward name (+1..+7 from that latest frame, L) is a defect when nothing else can explain it:

* the frame named, F, is in the log, heard more than the recorder's stamping jitter
  (``logs.STAMPING_S``, 1 ms) after the pose: the pose was on the bus before F was;
* the host heard the encoder sequence whole and at its cadence over the lap before F (F and
  its 16 predecessors, L among them: accepted, COUNTER +1 each, stamps 0.5..1.5 cycles apart,
  no refused frame between): no unheard frame of that COUNTER (16 before F) can be the one
  named, and no burst (a sender's backlog, a bus-off's release) puts the stamps off;
* the pose's own sender was on time over that lap: its frame and the ``ON_TIME_SENDS`` before
  it accepted, COUNTER +1 each, stamps 0.5..1.5 periods apart (a pose held back on the bus, the
  first after an MCU halt or a reboot, is heard after a silence or out of step, and may name a
  frame a lap behind, which the 4-bit name cannot tell from F);
* it does not repeat its predecessor's ENC_COUNTER (a firmware held on one frame, its E2E
  window shut, keeps naming it while the bus goes on: ``samples._held``).

The one frame a lap behind F that the name could also mean, F - 16, was heard 150 ms before the
pose; a firmware that had not taken the 15 frames heard since, while sending on time, has
none of the faults above (a stalled MCU sends nothing; its mailbox overflows only in a halt).

Within the stamping jitter (F heard at most 1 ms after the pose, or before it in time though
after it in the log) the log's order cannot be trusted over its stamps: a recorder that merges
its reads may write a pose line before its encoder line. That pose is no defect (``Named``'s
``reordered``); the judges still leave it out (``samples.match_encoder`` is causal: pairing it
in the whole log's judge alone made the streamed one's samples differ, tests/test_stream.py's
awkward log; ``tests/test_names_ahead.py`` keeps the case as a strict xfail).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import STAMPING_S, FrameArrays
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, ENC_COUNTER_MASK, POSE_PERIOD_S
from odocan.host.protocol.decode import BulkDecoder

HALF_LAP = ENC_COUNTER_LAP // 2  # a name is resolved -8..+7 from the latest frame
ON_TIME_SENDS = 8  # the pose sender's sends at cadence before it: a lap of encoder frames
CADENCE = (0.5, 1.5)  # a step of one period, in periods: the stamps' bounds
STAMP_S = 1e-6  # a log's stamp resolution: the jitter's bound read to it
POSES = ("ODOM_POSE_X", "ODOM_POSE_Y")
KEEP_ENC = 4 * ENC_COUNTER_LAP  # encoder frames carried from one feed to the next
KEEP_FOUND = 8  # findings kept (the earliest); all are counted

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]


@dataclass(frozen=True)
class Rows:
    """One message's frames in bus order: position in the log, stamp, E2E COUNTER, accepted;
    ``named``: ENC_COUNTER (pose frames; empty for encoder frames)."""

    pos: IntArray
    t: FloatArray
    counter: IntArray
    ok: BoolArray
    named: IntArray

    def join(self, other: Rows) -> Rows:
        return Rows(*(np.concatenate((a, b)) for a, b in zip(self.parts(), other.parts(),
                                                             strict=True)))

    def parts(self) -> tuple[Any, ...]:
        return self.pos, self.t, self.counter, self.ok, self.named

    def tail(self, start: int) -> Rows:
        return Rows(*(a[start:] for a in self.parts()))


def empty_rows() -> Rows:
    none = np.zeros(0, dtype=np.int64)
    return Rows(none, np.zeros(0), none, np.zeros(0, dtype=bool), none)


def run_lengths(rows: Rows, period_s: float) -> IntArray:
    """Per frame: how many frames before it run with it at the sender's cadence (accepted,
    COUNTER +1, stamps ``CADENCE`` periods apart); -1 for a frame not accepted."""
    n = len(rows.t)
    linked = np.zeros(n, dtype=bool)
    if n > 1:
        gap = np.diff(rows.t) / period_s
        linked[1:] = (((np.diff(rows.counter) & ENC_COUNTER_MASK) == 1) & (gap >= CADENCE[0])
                      & (gap <= CADENCE[1]) & rows.ok[1:] & rows.ok[:-1])
    at = np.arange(n)
    start = np.maximum.accumulate(np.where(linked, 0, at)) if n else at
    runs: IntArray = np.where(rows.ok, at - start, -1).astype(np.int64)
    return runs


def rows_of(frames: FrameArrays, accepted: BoolArray, decoder: BulkDecoder, name: str,
            offset: int = 0) -> Rows:
    """Every frame of ``name`` in ``frames`` (its positions ``offset`` on) as ``Rows``."""
    d = decoder.decode(frames, name)
    index = d["index"].astype(np.int64)
    named = d["ENC_COUNTER"].astype(np.int64) if "ENC_COUNTER" in d else index[:0]
    return Rows(index + offset, d["timestamp_s"].astype(np.float64),
                d["COUNTER"].astype(np.int64), accepted[index], named)


def cycle_of(decoder: BulkDecoder, name: str = "WHEEL_ENCODERS") -> float:
    """``name``'s DBC cycle time (s; 10 ms when it has none)."""
    return (decoder.message(name).cycle_time or 10) / 1000.0


@dataclass(frozen=True)
class Named:
    """Per pose frame: ``ahead`` (a defect: module docstring), ``reordered`` (F heard within the
    stamping jitter of it), ``decided`` (False: F not in the rows yet) and F (index into the
    encoder rows; -1: none)."""

    ahead: BoolArray
    reordered: BoolArray
    decided: BoolArray
    frame: IntArray


def names_ahead(enc: Rows, poses: Rows, cycle_s: float, period_s: float = POSE_PERIOD_S
                ) -> Named:
    """The rule of the module docstring over ``enc`` (every WHEEL_ENCODERS frame, bus order)
    and one pose message's frames ``poses`` (each at least ``ON_TIME_SENDS`` after its
    sender's first in the rows, to be judged)."""
    n, m = len(enc.t), len(poses.t)
    none = np.zeros(m, dtype=bool)
    kept = np.flatnonzero(enc.ok)
    if n == 0 or m == 0 or len(kept) == 0:
        return Named(none, none, np.ones(m, dtype=bool), np.full(m, -1, dtype=np.int64))
    before = np.searchsorted(enc.pos[kept], poses.pos) - 1
    latest = kept[np.maximum(before, 0)]
    step = ((poses.named - enc.counter[latest] + HALF_LAP) & ENC_COUNTER_MASK) - HALF_LAP
    forward = ((before >= 0) & (poses.t - enc.t[latest] < HALF_LAP * cycle_s) & (step >= 1)
               & poses.ok)
    frame = latest + step
    decided = ~forward | (frame < n)
    at = np.clip(frame, 0, n - 1)  # only judged rows read it: in bounds for every row
    enc_runs = run_lengths(enc, cycle_s)
    own_runs = run_lengths(poses, period_s)
    repeat = np.zeros(m, dtype=bool)
    repeat[1:] = poses.named[1:] == poses.named[:-1]
    judged = (forward & (frame < n) & (enc_runs[at] >= ENC_COUNTER_LAP)
              & (own_runs >= ON_TIME_SENDS) & ~repeat)
    late_s = enc.t[at] - poses.t
    ahead = judged & (late_s > STAMPING_S + STAMP_S)
    return Named(ahead, judged & ~ahead, decided, np.where(judged, frame, -1).astype(np.int64))


@dataclass(frozen=True)
class Ahead:
    """One pose frame naming a frame not yet sent: its message, stamp, ENC_COUNTER, and when
    the frame named was heard (s, the log's times)."""

    message: str
    t_s: float
    enc_counter: int
    sent_s: float

    def text(self, origin_s: float = 0.0) -> str:
        """In words, the times counted from ``origin_s`` (the live judges': the drive's first
        frame, as their other lines; a live stamp is the epoch's)."""
        return (f"{self.message} at {self.t_s - origin_s:.6f} s names WHEEL_ENCODERS COUNTER "
                f"{self.enc_counter}, not sent until {self.sent_s - origin_s:.6f} s")


def report_of(found: list[Ahead], count: int, origin_s: float = 0.0) -> dict[str, Any]:
    """The report's ``names_ahead``: ``frames`` (how many), ``first`` (the log's times) and
    ``detail`` (its times counted from ``origin_s``)."""
    first = found[0]
    more = f" (and {count - 1} more pose frames)" if count > 1 else ""
    return {"frames": count, "first": {"message": first.message, "t_s": first.t_s,
                                       "enc_counter": first.enc_counter,
                                       "sent_s": first.sent_s},
            "detail": f"{first.text(origin_s)}{more}: the firmware names an encoder frame "
                      "before it was sent"}


def mark(report: dict[str, Any], scan: AheadScan) -> dict[str, Any]:
    """``report`` with ``names_ahead`` and ``passed`` false when ``scan`` found any."""
    if scan.count:
        report["names_ahead"] = report_of(scan.found, scan.count)
        report["passed"] = False
    return report


def detail(report: dict[str, Any]) -> list[str]:
    """The FAIL reason of a report's ``names_ahead`` ([] without)."""
    ahead = report.get("names_ahead")
    return [str(ahead["detail"])] if ahead else []


@dataclass
class AheadScan:
    """``names_ahead`` over a log fed whole or chunk by chunk (the same findings): the encoder
    and pose frames of each chunk appended to those carried (``KEEP_ENC`` encoder frames, the
    pose frames not yet decided and the ``ON_TIME_SENDS`` before them)."""

    decoder: BulkDecoder
    found: list[Ahead] = field(default_factory=list)  # the ``KEEP_FOUND`` earliest
    count: int = 0
    _offset: int = 0
    _enc: Rows = field(default_factory=empty_rows)
    _poses: dict[str, Rows] = field(default_factory=dict)
    _done: dict[str, int] = field(default_factory=dict)  # per message: decided up to (pos)

    def feed(self, chunk: FrameArrays, accepted: BoolArray) -> None:
        """The next frames of the log (``accepted``: their E2E verdict)."""
        cycle_s = cycle_of(self.decoder)
        self._enc = self._enc.join(self._rows(chunk, accepted, "WHEEL_ENCODERS"))
        for name in POSES:
            rows = self._poses.get(name, empty_rows()).join(self._rows(chunk, accepted, name))
            self._poses[name] = self._judge(name, rows, cycle_s)
        self._enc = self._enc.tail(max(0, len(self._enc.t) - KEEP_ENC))
        self._offset += len(chunk)

    def _rows(self, chunk: FrameArrays, accepted: BoolArray, name: str) -> Rows:
        return rows_of(chunk, accepted, self.decoder, name, self._offset)

    def _judge(self, name: str, rows: Rows, cycle_s: float) -> Rows:
        """Record the frames of ``rows`` decided now; the rows to carry."""
        named = names_ahead(self._enc, rows, cycle_s)
        open_ = np.flatnonzero(~named.decided)
        first_open = int(open_[0]) if len(open_) else len(rows.t)
        now = (rows.pos > self._done.get(name, -1)) & (np.arange(len(rows.t)) < first_open)
        for k in np.flatnonzero(named.ahead & now).tolist():
            self.count += 1
            self.found.append(Ahead(name, float(rows.t[k]), int(rows.named[k]),
                                    float(self._enc.t[named.frame[k]])))
        self.found = sorted(self.found, key=lambda a: (a.t_s, a.message))[:KEEP_FOUND]
        if first_open:
            self._done[name] = int(rows.pos[first_open - 1])
        return rows.tail(max(0, first_open - ON_TIME_SENDS - 1))

