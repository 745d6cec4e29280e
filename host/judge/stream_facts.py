"""The analysis' facts about a log, gathered chunk by chunk (``host.io.logs.iter_log``), each
equal to what ``host.judge.analysis`` takes from the whole log (issue #14.1):

* the frames per DBC message (``analysis._frame_counts``) and the seconds of bus time the log
  covers (``analysis._covered_s``: first to last WHEEL_ENCODERS frame plus one cycle, or the
  first to the last frame);
* the integrator ODOM_STATUS reports (``samples.pick_integrator``: the last accepted summary's);
* the power-up rule's inputs (``powerup.starts_at_power_up`` and ``saw_only_the_log``): the
  first accepted summary's UPTIME, and the first accepted page of WHEEL_ENCODERS E2E counts
  (ENC_E2E_OK) with the number of accepted encoder frames before it was made
  (``powerup.made_at``: before it, or before the summary of its tick), and up to the frame
  the latest pose before that names (``powerup.pose_named``).

Carried: running counts, first and last times, the last INTEGRATOR value, the first UPTIME,
the first ENC_E2E_OK page, until it the last ``NAMED_SPAN`` accepted encoder COUNTERs.
Whether a page's signal is in the log is decided as ``BulkDecoder.decode_page`` decides it
over the whole log: present in every chunk that holds frames of that page (a page with no
frame at all in the log has every signal)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays, TimeOrder
from odocan.host.judge.finalstate import latched_fields
from odocan.host.judge.powerup import (
    NAMED_SPAN,
    holds_first_cycle,
    made_at,
    named_count,
    same_tick,
    status_counter_modulo,
    tick_bound_s,
    zero_first_sample,
)
from odocan.host.judge.powerup_times import TickTimes
from odocan.host.judge.reference import INTEGRATORS
from odocan.host.judge.samples import ENC_E2E_PAGE, AnalysisError, Poses, no_summary
from odocan.host.judge.statuslatch import StatusLatch, latch_summaries
from odocan.host.protocol import busfacts
from odocan.host.protocol.decode import BulkDecoder, DecodeError

SUMMARY_PAGE = busfacts.SUMMARY_PAGE  # ODOM_STATUS page with UPTIME and INTEGRATOR


@dataclass
class _Signal:
    """One signal of one ODOM_STATUS page over the chunks: is it in the page (AND over the
    chunks with frames of the page), its first and last accepted value and the first's
    position in the log."""

    present: bool = True
    first: int | None = None
    first_at: int | None = None
    last: int | None = None

    def feed(self, page: dict[str, np.ndarray], name: str, keep: npt.NDArray[np.bool_],
             offset: int) -> None:
        if len(page["index"]) == 0:
            return
        if name not in page:
            self.present = False
            return
        values = page[name][keep]
        if len(values) == 0:
            return
        if self.first is None:
            self.first = int(values[0])
            self.first_at = int(page["index"][keep][0]) + offset
        self.last = int(values[-1])


@dataclass
class StreamFacts:
    """The facts of the module docstring over a log fed chunk by chunk (``accepted``: the
    chunk's E2E-accepted mask from ``host.judge.stream.StreamE2E``)."""

    decoder: BulkDecoder
    frame_counts: dict[str, int] = field(default_factory=dict)  # analysis._frame_counts
    _offset: int = 0
    _first_s: float | None = None  # the log's first frame
    _last_s: float | None = None
    _enc_first_s: float | None = None  # every frame of WHEEL_ENCODERS' ID, accepted or not
    _enc_last_s: float | None = None
    _uptime: _Signal = field(default_factory=_Signal)
    _first_counter: _Signal = field(default_factory=_Signal)  # ODOM_STATUS's COUNTER, any page
    _integrator: _Signal = field(default_factory=_Signal)
    _enc_ok: _Signal = field(default_factory=_Signal)
    _enc_lost: _Signal = field(default_factory=_Signal)  # ENC_E2E_LOST of the same pages
    _has_status: bool = True  # the DBC's ODOM_STATUS is multiplexed
    _accepted_encoders: int = 0  # accepted WHEEL_ENCODERS frames before the first count page
    _summary: tuple[int, int] | None = None  # ... before the latest summary ahead of it, COUNTER
    _page_counter: int | None = None  # the first count page's COUNTER
    _named: tuple[int | None, int | None] = (None, None)  # powerup.pose_named: summary's, page's
    _tail: npt.NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, np.int64))
    _times: TickTimes = field(default_factory=TickTimes)  # powerup.heard_by_tick's evidence
    latch: StatusLatch = field(default_factory=StatusLatch)  # host.judge.statuslatch
    _order: TimeOrder = field(default_factory=TimeOrder)  # a log not in time order: said
    firmware_events: list[dict[str, Any]] = field(default_factory=list)  # ... its events

    def firmware_fields(self) -> dict[str, Any]:
        """The report's ``firmware_events`` and ``firmware_final`` (``host.judge.finalstate``)."""
        return latched_fields(self.firmware_events, self.latch)

    def feed(self, chunk: FrameArrays, accepted: npt.NDArray[np.bool_]) -> None:
        """Take the next chunk's facts."""
        self._order.feed(chunk)
        if len(chunk):
            if self._first_s is None:
                self._first_s = float(chunk.timestamp_s[0])
            self._last_s = float(chunk.timestamp_s[-1])
        counts = {}
        for message in self.decoder.db.messages:  # in the DBC's order, as the whole log's
            n = len(self.decoder.select(chunk, message.name)) + self.frame_counts.get(
                message.name, 0)
            if n:
                counts[message.name] = n
        self.frame_counts = counts
        self._feed_encoder_span(chunk)
        self._feed_status(chunk, accepted)
        self._offset += len(chunk)

    def _feed_encoder_span(self, chunk: FrameArrays) -> None:
        message = self.decoder.db.get_message_by_name("WHEEL_ENCODERS")
        stamps = chunk.timestamp_s[chunk.can_id == message.frame_id]
        if len(stamps):
            if self._enc_first_s is None:
                self._enc_first_s = float(stamps[0])
            self._enc_last_s = float(stamps[-1])

    def _feed_status(self, chunk: FrameArrays, accepted: npt.NDArray[np.bool_]) -> None:
        if not self._has_status:
            return
        try:
            summary = self.decoder.decode_page(chunk, "ODOM_STATUS", SUMMARY_PAGE)
            counts = self.decoder.decode_page(chunk, "ODOM_STATUS", ENC_E2E_PAGE)
        except (DecodeError, KeyError):  # no multiplexed ODOM_STATUS in the DBC
            self._has_status = False
            return
        keep = accepted[summary["index"]]
        self.firmware_events += latch_summaries(self.latch, summary, keep)
        self._uptime.feed(summary, "UPTIME", keep, self._offset)
        status = self.decoder.decode(chunk, "ODOM_STATUS")
        self._first_counter.feed(status, "COUNTER", accepted[status["index"]], self._offset)
        self._integrator.feed(summary, "INTEGRATOR", keep, self._offset)
        before = self._enc_ok.first is None
        self._enc_ok.feed(counts, "ENC_E2E_OK", accepted[counts["index"]], self._offset)
        self._enc_lost.feed(counts, "ENC_E2E_LOST", accepted[counts["index"]], self._offset)
        if before:
            self._feed_until_counts(chunk, accepted, summary, counts)

    def _feed_until_counts(self, chunk: FrameArrays, accepted: npt.NDArray[np.bool_],
                           summary: dict[str, np.ndarray], counts: dict[str, np.ndarray]) -> None:
        """Up to the first count page: the accepted encoder frames before it and before the
        latest accepted summary ahead of it, that summary's COUNTER, the page's COUNTER
        (``powerup.made_at``)."""
        limit = (len(chunk) if self._enc_ok.first_at is None
                 else self._enc_ok.first_at - self._offset)
        encoders = self.decoder.select(chunk, "WHEEL_ENCODERS")
        encoders = encoders[accepted[encoders]]
        named = _NamedBefore(chunk, accepted, self.decoder, (self._tail, self._accepted_encoders))
        heard = accepted[summary["index"]] & (summary["index"] < limit)
        if heard.any() and "COUNTER" in summary:
            at = int(summary["index"][heard][-1])
            self._summary = (self._accepted_encoders + int(np.count_nonzero(encoders < at)),
                             int(summary["COUNTER"][heard][-1]))
            self._named = (named.count(at, self._named[1]), self._named[1])
        self._named = (self._named[0], named.count(limit, self._named[1]))
        self._tail = named.tail(limit)
        self._accepted_encoders += int(np.count_nonzero(encoders < limit))
        self._times.feed(chunk, summary, heard, encoders[encoders < limit])
        if self._enc_ok.first_at is not None and "COUNTER" in counts:
            self._page_counter = int(counts["COUNTER"][accepted[counts["index"]]][0])

    @property
    def first_frame_s(self) -> float | None:
        """``reportfacts.first_frame_s`` of the frames fed."""
        return self._first_s

    def covered_s(self) -> float:
        """``analysis._covered_s`` of the frames fed."""
        message = self.decoder.db.get_message_by_name("WHEEL_ENCODERS")
        if self._enc_first_s is None or self._enc_last_s is None or not message.cycle_time:
            if self._first_s is None or self._last_s is None:
                return 0.0
            return float(self._last_s - self._first_s)
        return float(self._enc_last_s - self._enc_first_s) + message.cycle_time / 1000.0

    def integrator(self, given: str | None) -> tuple[str, str]:
        """``samples.pick_integrator`` of the frames fed."""
        if given is not None:
            if given not in INTEGRATORS:
                known = ", ".join(INTEGRATORS)
                raise AnalysisError(f"unknown integrator {given!r} (known: {known})")
            return given, "argument"
        try:
            signal = self.decoder.message("ODOM_STATUS").get_signal_by_name("INTEGRATOR")
        except (DecodeError, KeyError):
            signal = None
        last = self._integrator.last if self._has_status and self._integrator.present else None
        if signal is None or last is None:
            raise no_summary(self._order)
        choices: dict[Any, Any] = dict(signal.choices or {})
        name = str(choices.get(last, "")).lower()
        if name not in INTEGRATORS:
            raise AnalysisError(f"ODOM_STATUS reports an unknown integrator ({last})")
        return name, "ODOM_STATUS"

    def saw_only_the_log(self) -> bool:
        """``samples.saw_only_the_log`` of the frames fed."""
        return self._counted_only_the_log() is not False

    def _counted_only_the_log(self) -> bool | None:
        """``samples.counted_only_the_log`` of the frames fed."""
        if not self._has_status or not self._enc_ok.present or self._enc_ok.first is None:
            return None
        modulo = status_counter_modulo(self.decoder)
        made = made_at(self._accepted_encoders, self._page_counter, self._summary, modulo)
        at_summary = self._summary is not None and same_tick(self._page_counter,
                                                             self._summary[1], modulo)
        named = self._named[0] if at_summary else self._named[1]
        lost = self._enc_lost.first if self._enc_lost.present else None
        counts = {self._enc_ok.first, (self._enc_ok.first + (lost or 0)) & 0xFFFF}
        if made & 0xFFFF in counts or named in counts:
            return True
        cycle_ms = self.decoder.message("ODOM_STATUS").cycle_time
        if self._page_counter is None or not cycle_ms:
            return False
        bound_s = tick_bound_s(self._page_counter, self._times.summaries, modulo, cycle_ms)
        return bound_s is not None and self._times.before(bound_s, made) in counts

    def primed_late(self) -> bool:
        """The first count page may say the firmware primed on the log's k-th encoder frame
        (``powerup.primed_after``: k 1 or more, the first summary UPTIME 0 in its first
        cycle): the stream then reads the whole judge's candidates from the life's first
        frames (``stream_primed``; a gate wider than the rule: the event, when there is none,
        leaves the fitted start the whole log's judge takes too)."""
        if not self._has_status or not self._uptime.present or self._uptime.first != 0:
            return False
        if not self._enc_ok.present or self._enc_ok.first is None:
            return False
        if self._first_counter.present and not holds_first_cycle(self._first_counter.first):
            return False
        made = made_at(self._accepted_encoders, self._page_counter, self._summary,
                       status_counter_modulo(self.decoder))
        lost = self._enc_lost.first if self._enc_lost.present else None
        counts = {self._enc_ok.first, (self._enc_ok.first + (lost or 0)) & 0xFFFF}
        return any(made - count >= 1 for count in counts)

    def starts_at_power_up(self, first: Poses) -> bool:
        """``samples.starts_at_power_up``, given the log's first on-board sample (``first``:
        its columns, at least one element)."""
        if not self._has_status or not self._uptime.present or self._uptime.first != 0:
            return False
        counted = self._counted_only_the_log()
        if counted is None:
            return zero_first_sample(first)
        counter = self._first_counter.first if self._first_counter.present else None
        return counted and holds_first_cycle(counter)


class _NamedBefore:
    """``powerup.pose_named`` over a chunk, from the accepted encoder frames before it
    (``before``: the last ``NAMED_SPAN`` COUNTERs of them, how many in all)."""

    def __init__(self, chunk: FrameArrays, accepted: npt.NDArray[np.bool_],
                 decoder: BulkDecoder, before: tuple[npt.NDArray[np.int64], int]) -> None:
        try:
            self.poses = decoder.decode(chunk, "ODOM_POSE_X")
            encoders = decoder.decode(chunk, "WHEEL_ENCODERS")
        except DecodeError:
            self.poses, encoders = {}, {}
        if "ENC_COUNTER" not in self.poses or "COUNTER" not in encoders:
            self.poses = {}
            encoders = {"index": np.zeros(0, np.int64), "COUNTER": np.zeros(0, np.int64)}
        keep = accepted[encoders["index"]]
        self.index, self.counters = encoders["index"][keep], encoders["COUNTER"][keep]
        self.accepted, (self.before, self.heard) = accepted, before

    def count(self, at: int, earlier: int | None) -> int | None:
        """``named_count`` of the latest accepted pose before chunk position ``at``; ``earlier``
        (a previous chunk's) when there is none in the chunk."""
        if not self.poses:
            return None
        keep = self.accepted[self.poses["index"]] & (self.poses["index"] < at)
        if not keep.any():
            return earlier
        n = int(np.count_nonzero(self.index < int(self.poses["index"][keep][-1])))
        counters = np.concatenate((self.before, self.counters[:n]))
        return named_count(counters, self.heard + n, int(self.poses["ENC_COUNTER"][keep][-1]))

    def tail(self, at: int) -> npt.NDArray[np.int64]:
        """The last ``NAMED_SPAN`` accepted encoder COUNTERs before chunk position ``at``."""
        n = int(np.count_nonzero(self.index < at))
        return np.concatenate((self.before, self.counters[:n]))[-NAMED_SPAN:].astype(np.int64)
