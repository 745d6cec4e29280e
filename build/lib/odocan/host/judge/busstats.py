"""Measured bus load and per-message latency, set against the analysis' worst-case bounds.

Two sources (issue #16, part 3):

* **a bit-timed run** (``odocan run -b``): the wire itself (``sim.transport.BitTiming``) records
  for every frame when it was ready in its transmit buffer and when its end of frame came
  (``sim.canbits.LatencyStats``: streaming max and p99 per identifier, in whole bit times rounded
  up). The load is the bit times the wire was busy (frames plus their 3-bit interframe spaces)
  over the span from the first start of frame to the last end of frame.
* **a log** (``odocan analyze --bitrate``): only the load can be measured (a log does not say
  when a frame was queued): each frame's exact length (``sim.canbits.frame_bits``: its own stuff
  bits) plus the interframe space, over the span from the first frame's start (its timestamp
  minus its length: timestamps are end-of-frame receptions) to the last timestamp.

Each measured latency is compared with the worst-case response time R of the revised analysis of
Davis et al. 2007 (``host.judge.schedulability``) for the message of that identifier in the DBC.
R is measured from the nominal release and includes the queuing jitter J; the measured latency
starts when the frame was queued, so a measured maximum above R means the bus did something the
analysis' model excludes (a message sent more often than its period, a babbling node).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any, Protocol

import can
from cantools.database.can import Database

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.schedulability import NS_PER_S, BusLoad, analyse_bus, messages_from_dbc
from odocan.sim.canbits import INTERFRAME_BITS, LatencyHistogram, LatencyStats, frame_bits
from odocan.sim.exceptions import ConfigurationError

P99 = 0.99
_FLAG_EXTENDED, _FLAG_REMOTE, _FLAG_ERROR = 1, 2, 4


class TimedWire(Protocol):
    """What a bit-timed wire exposes (``sim.transport.BitTiming``)."""

    bitrate: int
    frames: int
    busy_bits: int
    latency: LatencyStats


@dataclass(frozen=True)
class MessageLatency:
    """One identifier's measured latency (ready to end of frame) and its analysed bound, in us."""

    name: str
    can_id: int  # -1: error frames
    extended: bool
    frames: int
    max_us: float | None  # None: no frame of it went out
    p99_us: float | None
    bound_us: float | None  # R of the revised analysis; None: not in the DBC, or no bound
    deadline_us: float | None
    late: int = 0  # frames whose latency passed the deadline (never understated)
    still_queued: int = 0  # frames still waiting for the bus when the run ended

    @property
    def starved(self) -> bool:
        """Frames of this DBC message came after their deadline, or never left the sender."""
        return self.deadline_us is not None and (self.late > 0 or self.still_queued > 0)

    @property
    def within_bound(self) -> bool | None:
        """max <= R (None when there is no R to compare with)."""
        if self.bound_us is None or self.max_us is None:
            return None
        return self.max_us <= self.bound_us

    def as_dict(self) -> dict[str, Any]:
        """The JSON report's row."""
        return {
            "name": self.name,
            "id": self.can_id,
            "extended": self.extended,
            "frames": self.frames,
            "max_latency_us": self.max_us,
            "p99_latency_us": self.p99_us,
            "bound_us": self.bound_us,
            "deadline_us": self.deadline_us,
            "within_bound": self.within_bound,
            "late": self.late,
            "still_queued": self.still_queued,
            "starved": self.starved,
        }


@dataclass(frozen=True)
class BusStats:
    """The measured bus: load over a span and, for a run, the per-message latencies."""

    source: str  # "run" (the wire's own records) or "log" (load only)
    bitrate: int
    frames: int
    busy_bits: int
    span_s: float
    messages: list[MessageLatency] = field(default_factory=list)
    analysis_note: str = ""  # why no bounds, when there are none

    @property
    def load(self) -> float | None:
        """Busy bit times over the span's bit times (None for an empty span)."""
        if self.span_s <= 0:
            return None
        return self.busy_bits / (self.span_s * self.bitrate)

    @property
    def within_bounds(self) -> bool | None:
        """Every bounded message's maximum within its R (None when none is bounded)."""
        checked = [m.within_bound for m in self.messages if m.within_bound is not None]
        return all(checked) if checked else None

    def as_dict(self) -> dict[str, Any]:
        """The report's ``bus`` section."""
        return {
            "source": self.source,
            "bitrate": self.bitrate,
            "frames": self.frames,
            "busy_bits": self.busy_bits,
            "span_s": self.span_s,
            "load": self.load,
            "latency": "ready in the transmit buffer to end of frame, us, rounded up to a bit time",
            "bound": "R, Davis et al. 2007 revised analysis of the DBC (from nominal release)",
            "within_bounds": self.within_bounds,
            "starved": [m.name for m in self.messages if m.starved],
            "analysis_note": self.analysis_note or None,
            "messages": [m.as_dict() for m in self.messages],
        }


def bounds_by_id(
    db: Database, bitrate: int, sporadic_ms: str | None = None
) -> tuple[dict[tuple[int, bool], tuple[str, int | None, int]], str]:
    """Per (ID, extended): (name, R ns or None, deadline ns) from the revised analysis of ``db``
    at ``bitrate``, and a note when the analysis gives none (utilization over 100 %)."""
    try:
        load: BusLoad = analyse_bus(messages_from_dbc(db, sporadic_ms=sporadic_ms), bitrate)
    except ConfigurationError as exc:
        names = {(m.frame_id, m.is_extended_frame): m.name for m in db.messages}
        return {key: (name, None, 0) for key, name in names.items()}, str(exc)
    out = {
        (m.can_id, m.extended): (m.name, r.r_ns, r.flow.d_ns)
        for m, r in zip(load.messages, load.responses, strict=True)
    }
    return out, ""


def pending_by_id(wire: TimedWire) -> dict[tuple[int, bool], int]:
    """Frames still in the transmit buffers, per (ID, extended): read it before the buses close
    (closing a handle drops its frames)."""
    out: dict[tuple[int, bool], int] = {}
    for pending in getattr(wire, "pending", ()):
        msg = pending[5]
        key = (-1, False) if msg.is_error_frame else (msg.arbitration_id, msg.is_extended_id)
        out[key] = out.get(key, 0) + 1
    return out


def from_wire(
    wire: TimedWire,
    db: Database,
    sporadic_ms: str | None = None,
    still_queued: dict[tuple[int, bool], int] | None = None,
) -> BusStats:
    """The measured load and latencies of a bit-timed run, each DBC message against its R and
    its deadline; every identifier the DBC does not know (a babbling node's) in one row.
    ``still_queued``: ``pending_by_id`` taken when the run ended."""
    stats = wire.latency
    bitrate = wire.bitrate
    bounds, note = bounds_by_id(db, bitrate, sporadic_ms)
    queued = still_queued or {}
    us_per_bit = 1e6 / bitrate
    rows = []
    for key in sorted(bounds, key=lambda k: (k[1], k[0])):
        name, r_ns, d_ns = bounds[key]
        hist = stats.by_id.get(key, LatencyHistogram())
        if not hist.count and not queued.get(key):
            continue  # a message this run never sent
        deadline_bits = d_ns * bitrate // NS_PER_S
        waiting = queued.get(key, 0)
        rows.append(_row(name, key, hist, us_per_bit, r_ns, d_ns, deadline_bits, waiting))
    others = [key for key in stats.by_id if key not in bounds]
    if others:
        merged = LatencyHistogram()
        for key in others:
            merged.merge(stats.by_id[key])
        waiting = sum(n for key, n in queued.items() if key not in bounds)
        name = f"(other: {len(others)} IDs)"
        rows.append(_row(name, (-2, False), merged, us_per_bit, None, 0, None, waiting))
    span_s = stats.last_end_s - stats.first_start_s if wire.frames else 0.0
    return BusStats("run", bitrate, wire.frames, wire.busy_bits, span_s, rows, note)


def _row(
    name: str,
    key: tuple[int, bool],
    hist: LatencyHistogram,
    us_per_bit: float,
    r_ns: int | None,
    d_ns: int,
    deadline_bits: int | None,
    still_queued: int,
) -> MessageLatency:
    return MessageLatency(
        name=name,
        can_id=key[0],
        extended=key[1],
        frames=hist.count,
        max_us=hist.max_bits * us_per_bit if hist.count else None,
        p99_us=hist.quantile_bits(P99) * us_per_bit if hist.count else None,
        bound_us=None if r_ns is None else r_ns / 1000,
        deadline_us=None if deadline_bits is None else d_ns / 1000,
        late=0 if deadline_bits is None else hist.count_above(deadline_bits),
        still_queued=still_queued,
    )


def frame_lengths_bits(frames: FrameArrays) -> Iterable[int]:
    """Each frame's exact length in bit times (its stuff bits, CRC-15 included; no IFS)."""
    for can_id, dlc, data, flags in zip(
        frames.can_id.tolist(), frames.dlc.tolist(), frames.data, frames.flags.tolist(),
        strict=True,
    ):
        msg = can.Message(
            arbitration_id=can_id,
            is_extended_id=bool(flags & _FLAG_EXTENDED),
            is_remote_frame=bool(flags & _FLAG_REMOTE),
            is_error_frame=bool(flags & _FLAG_ERROR),
            dlc=dlc,
            data=b"" if flags & _FLAG_REMOTE else bytes(data[:dlc]),
            check=False,
        )
        yield frame_bits(msg)


def from_frames(frames: FrameArrays, bitrate: int) -> BusStats:
    """The load of a log at ``bitrate``: exact frame lengths over the log's span (see above)."""
    lengths = list(frame_lengths_bits(frames))
    if not lengths:
        return BusStats("log", bitrate, 0, 0, 0.0)
    busy_bits = sum(lengths) + INTERFRAME_BITS * len(lengths)
    first_start_s = float(frames.timestamp_s[0]) - lengths[0] / bitrate
    span_s = float(frames.timestamp_s[-1]) - first_start_s
    return BusStats("log", bitrate, len(lengths), busy_bits, span_s)


LOAD_WINDOW_S = 1.0  # the live bus load is over the last second of bus time
LOAD_WINDOW_FRAMES = 16_384  # at most this many frames in it (a 1 Mbit/s bus carries < 21 000/s)


class LoadWindow:
    """The bus load over the last ``window_s`` of bus time, frame by frame, in bounded memory:
    each frame's exact length (``sim.canbits.frame_bits``, its own stuff bits) plus the 3-bit
    interframe space, summed over the frames whose end of frame (their timestamp) lies in the
    window. Before a full window has been heard, over the span since the first frame's start;
    when more than ``max_frames`` end within the window, over the frames kept."""

    def __init__(self, window_s: float = LOAD_WINDOW_S, max_frames: int = LOAD_WINDOW_FRAMES):
        self.window_s = window_s
        self._frames: deque[tuple[float, int]] = deque(maxlen=max_frames)
        self._bits = 0
        self._first_start_s: float | None = None
        self.capped = False  # frames left the window by its size, not its age

    def add(self, msg: can.Message) -> None:
        """One frame heard, stamped with its end of frame (s). Never raises: a frame whose
        length cannot be known (CAN FD) counts as nothing."""
        try:
            bits = frame_bits(msg) + INTERFRAME_BITS
        except ValueError:
            return
        t_s = msg.timestamp
        if self._first_start_s is None:
            self._first_start_s = t_s - bits * 1e-6  # at most 1 Mbit/s: a lower bound of SOF
        frames = self._frames
        if len(frames) == frames.maxlen:
            self._bits -= frames[0][1]
            self.capped = True
        frames.append((t_s, bits))
        self._bits += bits
        while frames and frames[0][0] <= t_s - self.window_s:
            self._bits -= frames.popleft()[1]

    def bits_per_s(self) -> float | None:
        """Bits on the wire per second over the window (None before any frame)."""
        frames = self._frames
        if not frames or self._first_start_s is None:
            return None
        if self.capped:  # the frames after the oldest kept, over the time since its end
            span_s = frames[-1][0] - frames[0][0]
            return (self._bits - frames[0][1]) / span_s if span_s > 0 else None
        span_s = min(self.window_s, frames[-1][0] - self._first_start_s)
        return self._bits / span_s if span_s > 0 else None

    def snapshot(self, bitrate: int | None) -> dict[str, Any]:
        """``bits_per_s``, and ``load`` (a fraction) when the bitrate is known."""
        rate = self.bits_per_s()
        return {
            "window_s": self.window_s,
            "frames": len(self._frames),
            "bits_per_s": rate,
            "bitrate": bitrate,
            "load": None if rate is None or not bitrate else rate / bitrate,
        }
