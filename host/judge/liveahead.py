"""``host.judge.namesahead``'s rule for the live judges (the monitor, the bridge), frame by frame
in plain Python: each WHEEL_ENCODERS, ODOM_POSE_X and ODOM_POSE_Y frame of the right length,
with its E2E verdict, in the order the judge takes them. A pose frame naming a frame ahead of
the latest accepted one waits for it (at most 7 encoder frames); heard, the frame decides it as
``namesahead.names_ahead`` does (the tests feed both one log: the same findings)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from odocan.host.io.logs import STAMPING_S
from odocan.host.judge.namesahead import (
    CADENCE,
    HALF_LAP,
    KEEP_FOUND,
    ON_TIME_SENDS,
    POSES,
    STAMP_S,
    Ahead,
    report_of,
)
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP, ENC_COUNTER_MASK, POSE_PERIOD_S

ENCODERS = "WHEEL_ENCODERS"


class _Run:
    """One message's latest frame: stamp, COUNTER, accepted, frames at cadence before it
    (``namesahead.run_lengths``), ENC_COUNTER."""

    __slots__ = ("counter", "named", "ok", "run", "t_s")

    def __init__(self) -> None:
        self.t_s, self.counter, self.ok, self.run, self.named = 0.0, -1, False, -1, -1

    def step(self, t_s: float, counter: int, ok: bool, period_s: float) -> int:
        """The next frame; its run length."""
        gap = (t_s - self.t_s) / period_s
        linked = (ok and self.ok and (counter - self.counter) & ENC_COUNTER_MASK == 1
                  and CADENCE[0] <= gap <= CADENCE[1])
        self.run = (self.run + 1 if linked else 0) if ok else -1
        self.t_s, self.counter, self.ok = t_s, counter, ok
        return self.run


class LiveAhead:
    """The pose frames naming an encoder frame not yet sent, found live (``found``: the
    ``KEEP_FOUND`` earliest; ``count``: all)."""

    def __init__(self, db: Any) -> None:
        self.cycle_s = (db.get_message_by_name(ENCODERS).cycle_time or 10) / 1000.0
        self.found: list[Ahead] = []
        self.count = 0
        self.origin_s: float | None = None  # the times said count from here (the first frame)
        self._enc = _Run()
        self._enc_n = 0  # encoder frames heard (the next one's number)
        self._latest: tuple[int, float, int] | None = None  # latest accepted: number, t, COUNTER
        self._poses = {name: _Run() for name in POSES}
        self._fields = {name: _field(db, name) for name in POSES}
        self._waiting: list[tuple[int, str, float, int]] = []  # frame named, pose, t, ENC_COUNTER

    def hearer(self, name: str) -> Callable[[float, bytes, bool], None] | None:
        """``heard`` for one message (None for the others: nothing to call)."""
        if name != ENCODERS and name not in self._fields:
            return None
        return lambda t_s, data, ok: self.heard(name, t_s, data, ok)

    def heard(self, name: str, t_s: float, data: bytes, ok: bool) -> None:
        """One frame of ``name`` (of its length; ``ok``: E2E accepted)."""
        self.origin_s = t_s if self.origin_s is None else self.origin_s
        counter = data[1] & ENC_COUNTER_MASK
        if name == ENCODERS:
            self._encoder(t_s, counter, ok)
        elif name in self._fields:
            self._pose(name, t_s, counter, ok, self._fields[name](data))

    def _encoder(self, t_s: float, counter: int, ok: bool) -> None:
        run = self._enc.step(t_s, counter, ok, self.cycle_s)
        number = self._enc_n
        self._enc_n += 1
        if ok:
            self._latest = (number, t_s, counter)
        if not self._waiting:
            return
        for frame, pose, pose_t, named in self._waiting:
            late_s = t_s - pose_t
            if frame == number and run >= ENC_COUNTER_LAP and late_s > STAMPING_S + STAMP_S:
                self._found(Ahead(pose, pose_t, named, t_s))
        self._waiting = [w for w in self._waiting if w[0] > number]

    def _pose(self, name: str, t_s: float, counter: int, ok: bool, named: int) -> None:
        own = self._poses[name]
        repeat = own.named == named
        own.named = named
        run = own.step(t_s, counter, ok, POSE_PERIOD_S)
        if self._latest is None or run < ON_TIME_SENDS or repeat:
            return
        number, latest_t, latest_counter = self._latest
        step = ((named - latest_counter + HALF_LAP) & ENC_COUNTER_MASK) - HALF_LAP
        if step >= 1 and t_s - latest_t < HALF_LAP * self.cycle_s:
            self._waiting.append((number + step, name, t_s, named))

    def _found(self, ahead: Ahead) -> None:
        self.count += 1
        self.found = sorted([*self.found, ahead], key=lambda a: (a.t_s, a.message))[:KEEP_FOUND]

    def why(self) -> list[str]:
        """The live verdict's reason ([] when none was found)."""
        return [str(report_of(self.found, self.count, self.origin_s or 0.0)["detail"])] \
            if self.count else []

    def as_dict(self) -> dict[str, Any] | None:
        """``namesahead.report_of`` (None when none was found)."""
        return report_of(self.found, self.count, self.origin_s or 0.0) if self.count else None


def _field(db: Any, name: str) -> Callable[[bytes], int]:
    """ENC_COUNTER's raw value from a frame of ``name`` (little-endian, unsigned, DBC)."""
    signal = db.get_message_by_name(name).get_signal_by_name("ENC_COUNTER")
    start, mask = int(signal.start), (1 << int(signal.length)) - 1
    assert signal.byte_order == "little_endian"
    return lambda data: (int.from_bytes(data, "little") >> start) & mask
