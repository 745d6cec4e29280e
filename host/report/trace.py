"""What the monitor's trace sees: every frame decoded from the DBC, filtered, frozen while paused,
and the rate of each page of a multiplexed message (``PageRates``, counted here from the frames
the trace decodes, not by the model). The screen (``host.report.tui``) draws it.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import can
from cantools.database.can import Database, Message
from cantools.database.namedsignalvalue import NamedSignalValue

from odocan.host.protocol.decode import frame_key
from odocan.sim.exceptions import ConfigurationError

TRACE_LINES = 500  # decoded frames kept for the trace
PAGE_WINDOW = 32  # frames per page for a page's rate
_HIDDEN = frozenset({"CHECKSUM", "COUNTER"})


MAX_CAN_ID = 0x1FFFFFFF  # the largest 29-bit identifier


@dataclass(frozen=True)
class FrameFilter:
    """Which frames the trace shows: by message name or by CAN ID (empty: all)."""

    names: frozenset[str] = frozenset()
    ids: frozenset[int] = frozenset()
    text: str = ""

    @classmethod
    def parse(cls, specs: Sequence[str], db: Database) -> FrameFilter:
        """``NAME`` (a DBC message, any case) or ``0xID`` items, also comma-separated."""
        names, ids = set(), set()
        known = {m.name.upper() for m in db.messages}
        items = [item.strip() for spec in specs for item in spec.split(",") if item.strip()]
        for item in items:
            if item.lower().startswith("0x"):
                try:
                    can_id = int(item, 16)
                except ValueError:
                    raise ConfigurationError(f"--filter {item}: not a hexadecimal CAN ID") from None
                if can_id > MAX_CAN_ID:  # no frame can match: the trace would stay empty
                    raise ConfigurationError(
                        f"--filter {item}: beyond the 29-bit CAN IDs (at most 0x{MAX_CAN_ID:X})")
                ids.add(can_id)
            elif item.upper() in known:
                names.add(item.upper())
            else:
                raise ConfigurationError(
                    f"--filter {item}: no such message in the DBC (give a name or 0xID)")
        return cls(frozenset(names), frozenset(ids), ",".join(items))

    def matches(self, arbitration_id: int, name: str | None) -> bool:
        """True when the frame is shown."""
        if not self.names and not self.ids:
            return True
        return arbitration_id in self.ids or (name is not None and name.upper() in self.names)


class PageRate(NamedTuple):
    """One page of a multiplexed message: its multiplexer value, name and rate (Hz)."""

    number: int
    name: str
    rate_hz: float | None  # None before two frames


@dataclass
class PageRates:
    """Frame rate of each page of each multiplexed message, from bus timestamps."""

    times: dict[tuple[str, int], deque[float]] = field(default_factory=dict)
    names: dict[tuple[str, int], str] = field(default_factory=dict)

    def heard(self, message: str, number: int, name: str, timestamp_s: float) -> None:
        """One frame of ``message``'s page ``number`` (``name``) at ``timestamp_s`` (bus, s)."""
        key = (message, number)
        if key not in self.times:
            self.times[key] = deque(maxlen=PAGE_WINDOW)
            self.names[key] = name
        self.times[key].append(timestamp_s)

    def rates_hz(self, message: str) -> list[PageRate]:
        """The pages heard of ``message``, by multiplexer value, with their rates."""
        out = []
        for (name, number), times in sorted(self.times.items()):
            if name == message:
                span_s = times[-1] - times[0]
                rate_hz = (len(times) - 1) / span_s if len(times) > 1 and span_s > 0 else None
                out.append(PageRate(number, self.names[(name, number)], rate_hz))
        return out


@dataclass(frozen=True)
class TraceLine:
    """One decoded frame as the trace shows it."""

    timestamp_s: float
    arbitration_id: int
    name: str  # "?" when the ID is not in the DBC
    text: str


class Trace:
    """The latest decoded frames (filtered, frozen while paused) and the per-page rates."""

    def __init__(self, db: Database, frame_filter: FrameFilter | None = None,
                 lines: int = TRACE_LINES) -> None:
        self.db = db
        self.filter = frame_filter or FrameFilter()
        self.lines: deque[TraceLine] = deque(maxlen=lines)
        self.pages = PageRates()
        self.paused = False
        self.hidden_while_paused = 0
        self.first_s: float | None = None  # bus time of the first frame (the trace's zero)
        self._by_key = {frame_key(m.frame_id, m.is_extended_frame): m for m in db.messages}

    def feed(self, msg: can.Message) -> None:
        """Decode one frame: count its page, and keep it unless paused or filtered out."""
        if self.first_s is None:
            self.first_s = msg.timestamp
        if msg.is_error_frame or msg.is_remote_frame:
            self._keep(msg, "?", "error frame" if msg.is_error_frame else "remote frame")
            return
        message = self._by_key.get(frame_key(msg.arbitration_id, msg.is_extended_id))
        if message is None:
            self._keep(msg, "?", bytes(msg.data).hex(" "))
            return
        text, page = _decoded(message, bytes(msg.data))
        if page is not None:
            self.pages.heard(message.name, *page, msg.timestamp)
        self._keep(msg, message.name, text)

    def _keep(self, msg: can.Message, name: str, text: str) -> None:
        if not self.filter.matches(msg.arbitration_id, None if name == "?" else name):
            return
        if self.paused:
            self.hidden_while_paused += 1
            return
        self.lines.append(TraceLine(msg.timestamp, msg.arbitration_id, name, text))

    def toggle_pause(self) -> None:
        """Freeze or resume the trace (the statistics never stop)."""
        self.paused = not self.paused
        self.hidden_while_paused = 0


def _decoded(message: Message, data: bytes) -> tuple[str, tuple[int, str] | None]:
    """The frame's signals as text, and its page (number, name) when it is multiplexed."""
    try:
        signals = message.decode(data, decode_choices=True, allow_truncated=True)
    except Exception:  # cantools: wrong length, unknown page ... (never fatal)
        return f"undecodable {data.hex(' ')}", None
    assert isinstance(signals, dict)
    page = None
    muxes = [s.name for s in message.signals if s.is_multiplexer]
    if muxes and muxes[0] in signals:
        value = signals[muxes[0]]
        number = value.value if isinstance(value, NamedSignalValue) else value
        page = (int(number), str(value))
    parts = []
    for name, value in signals.items():
        if name in _HIDDEN:
            continue
        shown = f"{value:.4f}".rstrip("0").rstrip(".") if isinstance(value, float) else str(value)
        parts.append(f"{name} {shown}")
    return " ".join(parts), page
