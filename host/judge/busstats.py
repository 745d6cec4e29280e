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

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any, Protocol

import can
from cantools.database.can import Database

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.schedulability import BusLoad, analyse_bus, messages_from_dbc
from odocan.sim.canbits import INTERFRAME_BITS, LatencyStats, frame_bits
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
    max_us: float
    p99_us: float
    bound_us: float | None  # R of the revised analysis; None: not in the DBC, or no bound
    deadline_us: float | None

    @property
    def within_bound(self) -> bool | None:
        """max <= R (None when there is no R to compare with)."""
        return None if self.bound_us is None else self.max_us <= self.bound_us

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


def from_wire(wire: TimedWire, db: Database, sporadic_ms: str | None = None) -> BusStats:
    """The measured load and latencies of a bit-timed run, each against the DBC's R."""
    stats = wire.latency
    bitrate = wire.bitrate
    bounds, note = bounds_by_id(db, bitrate, sporadic_ms)
    us_per_bit = 1e6 / bitrate
    rows = []
    for key in sorted(stats.by_id):
        hist = stats.by_id[key]
        name, r_ns, d_ns = bounds.get(key, (_unknown_name(key), None, 0))
        rows.append(
            MessageLatency(
                name=name,
                can_id=key[0],
                extended=key[1],
                frames=hist.count,
                max_us=hist.max_bits * us_per_bit,
                p99_us=hist.quantile_bits(P99) * us_per_bit,
                bound_us=None if r_ns is None else r_ns / 1000,
                deadline_us=d_ns / 1000 if r_ns is not None else None,
            )
        )
    span_s = stats.last_end_s - stats.first_start_s if wire.frames else 0.0
    return BusStats("run", bitrate, wire.frames, wire.busy_bits, span_s, rows, note)


def _unknown_name(key: tuple[int, bool]) -> str:
    if key[0] < 0:
        return "(error frames)"
    return f"(0x{key[0]:08X})" if key[1] else f"(0x{key[0]:03X})"


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
