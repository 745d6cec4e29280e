"""The encoder frames the firmware lost that the log holds, chunk by chunk (issue #14.1):
``host.judge.losses.firmware_losses`` over a life fed in chunks, its spans the whole life's.

Carried: the last ENC_E2E_LOST page (its count, the latest encoder frame before it and that
frame's sequence number: ``losses.lost_beyond_gaps`` runs on it and the chunk's pages), the
encoder frames counted so far with the last one's sequence number, and whether a summary saying
MAILBOX_OVERFLOW came after the last page (``losses.overflow_reported_after`` per chunk).

The streamed analysis does not place the allowance itself (its per-sample sums of the largest
merge errors): a life with a span is refused (``stream_analysis.NotStreamable``) and analysed
whole; without one the allowance is 0 everywhere, as in the whole log."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.gapbound import period_bounds
from odocan.host.judge.losses import (
    LOST_PAGE,
    OneSteps,
    heading_steps,
    lost_beyond_gaps,
    ok_count_spans,
    ok_growth_of,
    overflow_reported_after,
    placement_accounted,
    stall_placements,
    step_vector,
    totals_growth,
    worst_runs_m,
)
from odocan.host.judge.lossgate import Gate, gated_counts
from odocan.host.judge.reference import Geometry, wrap_delta
from odocan.host.judge.samples import (
    Encoders,
    FloatArray,
    IntArray,
    contract_cycle_s,
    queued_frames,
)
from odocan.host.judge.swappedskips import refused_places, widened
from odocan.host.protocol.busfacts import TOTALS_PAGE
from odocan.host.protocol.decode import BulkDecoder, DecodeError


@dataclass
class StreamLosses:
    """``firmware_losses`` chunk by chunk: ``feed`` each chunk with its accepted mask and
    ``StreamEncoders``' frames, then ``spans``. Carried: every accepted ENC_E2E_LOST page
    (the latest encoder frame before it, that frame's sequence number, its count, its time) and
    every accepted summary page's time with the encoder frames stamped at or before it (a few
    numbers per status period), for ``losses._made_from``'s start of each span."""

    decoder: BulkDecoder
    _offset: int = 0  # frames before the chunk
    _enc_count: int = 0  # accepted encoder frames before the chunk
    _last_seq: int = 0  # the sequence number of the last of them
    _last_enc_t: float = -math.inf  # the time of the last of them
    _pages: list[tuple[int, int, int, float]] = field(default_factory=list)  # upto, seq, lost, t
    _ok: list[int] | None = field(default_factory=list)  # their ENC_E2E_OK (None: no signal)
    _totals: list[tuple[float, int]] = field(default_factory=list)  # FRAME_TOTALS: t, LOST
    _summaries_t: list[float] = field(default_factory=list)  # accepted page 0 times
    _summaries_upto: list[int] = field(default_factory=list)  # encoder frames stamped <= each
    _in_order: bool = True  # no summary stamped before an encoder frame of an earlier chunk
    _signal: bool = True  # the DBC's ODOM_STATUS has ENC_E2E_LOST
    _overflow_after: bool = False  # a MAILBOX_OVERFLOW summary after the last page
    _refused: list[IntArray] = field(default_factory=list)  # swappedskips.refused_places
    _last_counter: int | None = None  # the COUNTER of the last accepted encoder frame

    @property
    def exact(self) -> bool:
        """Whether ``spans`` is the whole life's (summary times in order with the frames')."""
        return self._in_order

    def feed(self, chunk: FrameArrays, accepted: npt.NDArray[np.bool_], enc: Encoders) -> None:
        """Take the next chunk (``enc``: its accepted encoder frames, ``index`` in the log)."""
        page = self._page_rows(chunk)
        keep = accepted[page["index"]] if page else np.zeros(0, dtype=bool)
        index = page["index"][keep] if page else np.zeros(0, dtype=np.int64)
        if len(index):
            self._add_pages(index + self._offset, page["ENC_E2E_LOST"][keep].astype(np.int64),
                            chunk.timestamp_s[index], enc)
            if self._ok is not None and "ENC_E2E_OK" in page:
                self._ok += page["ENC_E2E_OK"][keep].astype(np.int64).tolist()
            else:
                self._ok = None
        self._add_totals(chunk, accepted)
        reported = overflow_reported_after(chunk, accepted, self.decoder,
                                            int(index[-1]) if len(index) else -1)
        self._overflow_after = reported if len(index) else (self._overflow_after or reported)
        self._add_summaries(chunk, accepted, enc)
        self._refused.append(self._enc_count + refused_places(
            chunk, accepted, self.decoder, enc.index, enc.counter, self._offset,
            self._last_counter))
        if len(enc.counter):
            self._last_counter = int(enc.counter[-1])
        self._offset += len(chunk)
        self._enc_count += len(enc.index)
        if len(enc.seq):
            self._last_seq = int(enc.seq[-1])
            self._last_enc_t = float(enc.timestamp_s[-1])

    def spans(self, power_up: bool = False) -> list[tuple[int, int, int]]:
        """``firmware_losses`` of the life fed: (first, last, n) per span; ``power_up``: its
        power-up page of 0 lost at the first encoder frame before the first page."""
        n_enc = self._enc_count
        if not self._signal or n_enc < 2:
            return []
        spans: list[tuple[int, int, int]] = []
        if self._pages:
            upto, seq, lost = (np.array([p[k] for p in self._pages], dtype=np.int64)
                               for k in range(3))
            made = self._made_from(upto, np.array([p[3] for p in self._pages]))
            if power_up:  # ENC_E2E_LOST counted from 0 on the primed frame (sequence 0)
                upto, seq, lost, made = (np.concatenate(([0], a)) for a in (upto, seq, lost, made))
            excess = lost_beyond_gaps(lost[:-1], lost[1:], seq[:-1], seq[1:], np.diff(upto),
                                      at_most=upto[1:] - made[:-1],
                                      ok_growth=self._ok_growth(power_up),
                                      total_growth=self._total_growth(power_up))
            spans = [(int(made[k]), int(upto[k + 1]), int(excess[k]))
                     for k in np.flatnonzero(excess > 0)]
        tail = self._pages[-1][0] if self._pages else 0
        if self._overflow_after:
            spans.append((tail, n_enc - 1, n_enc - 1 - tail))
        return spans

    def _ok_growth(self, power_up: bool) -> IntArray | None:
        """ENC_E2E_OK's growth between consecutive pages (``losses._ok_growth``)."""
        if self._ok is None:
            return None
        return ok_growth_of(np.array(self._ok, dtype=np.int64), power_up)

    def _add_totals(self, chunk: FrameArrays, accepted: npt.NDArray[np.bool_]) -> None:
        """The chunk's accepted FRAME_TOTALS pages' times and LOST_FRAMES."""
        try:
            totals = self.decoder.decode_page(chunk, "ODOM_STATUS", TOTALS_PAGE)
        except DecodeError:
            return
        if "LOST_FRAMES" in totals and len(totals["index"]):
            keep = totals["index"][accepted[totals["index"]]]
            lost = totals["LOST_FRAMES"][accepted[totals["index"]]].astype(np.int64)
            self._totals += zip(chunk.timestamp_s[keep].tolist(), lost.tolist(), strict=True)

    def _total_growth(self, power_up: bool) -> IntArray | None:
        """``losses._total_growth`` by the pages' times (None: no FRAME_TOTALS page)."""
        if not self._totals:
            return None
        t = np.array([a for a, _ in self._totals])
        total = np.array([b for _, b in self._totals], dtype=np.int64)
        return totals_growth(t, total, np.array([p[3] for p in self._pages]), power_up)

    def ok_spans(self, power_up: bool = False) -> list[tuple[int, int, int]]:
        """``losses.firmware_ok_spans`` of the life fed (``power_up``: ENC_E2E_OK 1 at the
        primed frame, the first)."""
        if not self._signal or self._ok is None or not self._pages or self._enc_count < 2:
            return []
        upto = np.array([p[0] for p in self._pages], dtype=np.int64)
        made = self._made_from(upto, np.array([p[3] for p in self._pages]))
        ok = np.array(self._ok, dtype=np.int64)
        if power_up:
            ok, upto, made = (np.concatenate(([first], a)) for first, a in ((1, ok), (0, upto),
                                                                            (0, made)))
        return widened(ok_count_spans(ok, upto, made), np.concatenate(
            [np.zeros(0, dtype=np.int64), *self._refused]))  # swappedskips

    def _made_from(self, upto: IntArray, page_t: FloatArray) -> IntArray:
        """``losses._made_from`` from the carried summaries."""
        cycle_s = contract_cycle_s(self.decoder, "WHEEL_ENCODERS")
        if cycle_s is None or not self._summaries_t:
            return upto
        sent_s = np.array(self._summaries_t)
        on_time = ~queued_frames(sent_s, cycle_s)
        stamped = np.array(self._summaries_upto, dtype=np.int64)[on_time]
        k = np.searchsorted(sent_s[on_time], page_t, side="right") - 1
        at = np.where(k >= 0, stamped[np.maximum(k, 0)], 0)
        made: IntArray = np.minimum(upto, np.maximum(at - 1, 0))
        return made

    def _add_pages(
        self, index: npt.NDArray[np.int64], lost: npt.NDArray[np.int64], t_s: FloatArray,
        enc: Encoders,
    ) -> None:
        """The chunk's pages (``index`` in the log, ``t_s`` their times)."""
        before = np.searchsorted(enc.index, index)  # the chunk's encoder frames before each
        upto = np.maximum(self._enc_count + before - 1, 0)
        seq = np.where(before > 0, enc.seq[np.maximum(before - 1, 0)] if len(enc.seq)
                       else 0, self._last_seq if self._enc_count else 0)  # (seq[0] is 0)
        self._pages += zip(upto.tolist(), seq.tolist(), lost.tolist(), t_s.tolist(),
                           strict=True)

    def _add_summaries(
        self, chunk: FrameArrays, accepted: npt.NDArray[np.bool_], enc: Encoders
    ) -> None:
        """The chunk's accepted summary pages, each with the encoder frames stamped at or before
        it (``np.searchsorted(enc.timestamp_s, t, side="right")`` over the life's frames, whose
        times do not go back): those still open take the chunk's frames stamped at their time."""
        stamps = enc.timestamp_s
        for k in range(len(self._summaries_t) - 1, -1, -1):  # the open ones: at the end
            t = self._summaries_t[k]
            if t < self._last_enc_t:
                break
            self._summaries_upto[k] += int(np.searchsorted(stamps, t, side="right"))
        try:
            rows = self.decoder.decode_page(chunk, "ODOM_STATUS", 0)["index"]
        except DecodeError:
            return
        t_s = chunk.timestamp_s[rows[accepted[rows]]]
        if np.any(t_s < self._last_enc_t):
            self._in_order = False
        self._summaries_t += t_s.tolist()
        self._summaries_upto += (self._enc_count
                                 + np.searchsorted(stamps, t_s, side="right")).tolist()

    def _page_rows(self, chunk: FrameArrays) -> dict[str, np.ndarray]:
        """The chunk's ENC_E2E_LOST pages ({} without that signal in the DBC)."""
        try:
            page = self.decoder.decode_page(chunk, "ODOM_STATUS", LOST_PAGE)
        except DecodeError:
            self._signal = False
            return {}
        if "ENC_E2E_LOST" not in page:
            self._signal = False
            return {}
        return page


@dataclass
class SpanDrops:
    """``losses.loss_allowance`` for the spans of a life (``StreamLosses.spans``) from a pass
    over its encoder frames (``feed``) and its kept on-board samples (``named``): each frame's
    cumulative counts (the firmware's: ``lossgate.gated_counts``, carried across chunks),
    heading and single-step displacement (``losses.OneSteps``: continued cumulative sums,
    bit for bit the whole life's), kept only from the frame before each span to the frame
    after it; then each span's weight (``losses.worst_runs_m`` on them, the frames a
    sample names excepted, and those a stall's placement accounts for: ``breaks``, the life's
    stalls and holds, ``losses.stall_placements``) and the allowance at any encoder frame (the
    weights of the spans that began before it, added in the same order)."""

    spans: list[tuple[int, int, int]]
    geometry: Geometry
    bits: int
    integrator: str
    breaks: list[int] = field(default_factory=list)
    _placed_at: dict[int, int] = field(default_factory=dict)  # break -> first sample after
    _count: int = 0  # encoder frames fed
    _last: tuple[int, int, int, int, float, float, float] | None = None  # gated l, r; cum l,
    # r; heading, cum x, cum y of the last frame fed
    _gate: Gate | None = None  # ``lossgate.gated_counts``' state after the frames fed
    _kept: dict[int, tuple[int, int, float, float, float]] = field(default_factory=dict)
    _named: set[int] = field(default_factory=set)  # frames near a span a sample names
    _sums: FloatArray | None = None  # weights added up, span by span

    def feed(self, enc: Encoders) -> None:
        """The life's next accepted encoder frames."""
        if len(enc.index) == 0:
            return
        g, last = self.geometry, self._last
        left, right, self._gate = gated_counts(enc.left.astype(np.int64),
                                               enc.right.astype(np.int64), enc.seq,
                                               period_bounds(g), self.bits, self._gate)
        if last is not None:
            left, right = np.r_[last[0], left], np.r_[last[1], right]
        dl = wrap_delta(np.diff(left), self.bits)
        dr = wrap_delta(np.diff(right), self.bits)
        start = (0, 0, 0.0, 0.0, 0.0) if last is None else last[2:]
        heading = np.cumsum(np.concatenate(([start[2]], heading_steps(dl, dr, g))))
        one_x, one_y = step_vector(dl, dr, heading[:-1], heading[1:], g, self.integrator)
        cum_l = np.cumsum(np.concatenate(([start[0]], dl)))
        cum_r = np.cumsum(np.concatenate(([start[1]], dr)))
        cum_x = np.cumsum(np.concatenate(([start[3]], one_x)))
        cum_y = np.cumsum(np.concatenate(([start[4]], one_y)))
        skip = 0 if last is None else 1  # element 0 is the last frame fed, kept already
        frames = self._count + np.arange(len(heading) - skip)
        for k in np.flatnonzero(self._near(frames)).tolist():
            j = k + skip
            self._kept[int(frames[k])] = (int(cum_l[j]), int(cum_r[j]), float(heading[j]),
                                          float(cum_x[j]), float(cum_y[j]))
        self._count += len(enc.index)
        self._last = (int(left[-1]), int(right[-1]), int(cum_l[-1]), int(cum_r[-1]),
                      float(heading[-1]), float(cum_x[-1]), float(cum_y[-1]))

    def named(self, sample_enc: npt.NDArray[np.int64]) -> None:
        """Kept on-board samples' encoder frames: a frame a sample names was not lost; the
        first at or after each break is where its placement is made."""
        self._named.update(sample_enc[self._near(sample_enc)].tolist())
        for b in self.breaks:
            later = sample_enc[sample_enc >= b]
            if len(later):
                first = int(np.min(later))
                self._placed_at[b] = min(first, self._placed_at.get(b, first))

    def allowance(self, at: npt.NDArray[np.int64]) -> FloatArray:
        """``loss_allowance`` at encoder frames ``at`` (0 everywhere without a span)."""
        if not self.spans:
            return np.zeros(len(at))
        sums = self._weights()
        begun = np.searchsorted(np.array([s[0] for s in self.spans], dtype=np.int64), at,
                                side="left")  # spans whose first frame is before each
        out: FloatArray = np.where(begun > 0, sums[np.maximum(begun - 1, 0)], 0.0)
        return out

    def _weights(self) -> FloatArray:
        if self._sums is None:
            total, sums = 0.0, []
            for first, last, n in self.spans:  # loss_allowance's order: 0.0 + w1 + w2 + ...
                total = total + self._weight(first, last, n)
                sums.append(total)
            self._sums = np.array(sums, dtype=np.float64)
        return self._sums

    def _weight(self, first: int, last: int, n: int) -> float:
        """``worst_runs_m`` of one span on the frames kept around it, from the frame before it
        to the frame after it: in local positions its frames are never the window's ends
        unless they are the life's, which ``worst_runs_m`` never loses either."""
        lo, hi = max(first - 1, 0), min(last + 1, self._count - 1)
        rows = [self._kept[g] for g in range(lo, hi + 1)]
        steps = OneSteps(
            self.geometry, self.integrator,
            np.array([r[0] for r in rows], dtype=np.int64),
            np.array([r[1] for r in rows], dtype=np.int64),
            np.array([r[2] for r in rows]), np.array([r[3] for r in rows]),
            np.array([r[4] for r in rows]),
        )
        lost_ok = np.array([g not in self._named for g in range(lo, hi + 1)], dtype=bool)
        placed = stall_placements(np.array(self.breaks, dtype=np.int64),
                                  np.array(list(self._placed_at.values()), dtype=np.int64))
        lost_ok &= ~placement_accounted(np.arange(lo, hi + 1), placed)
        return worst_runs_m(steps, lost_ok, first - lo, last - lo, n)

    def _near(self, frames: npt.NDArray[np.int64]) -> npt.NDArray[np.bool_]:
        """Which ``frames`` lie from the frame before a span to the frame after it."""
        if not self.spans:
            return np.zeros(len(frames), dtype=bool)
        firsts = np.array([s[0] - 1 for s in self.spans], dtype=np.int64)
        lasts = np.maximum.accumulate(np.array([s[1] + 1 for s in self.spans], dtype=np.int64))
        k = np.searchsorted(firsts, frames, side="right") - 1
        near: npt.NDArray[np.bool_] = (k >= 0) & (frames <= lasts[np.maximum(k, 0)])
        return near
