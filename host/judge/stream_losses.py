"""The encoder frames the firmware lost that the log holds, chunk by chunk (issue #14.1):
``host.judge.compare.firmware_losses`` over a life fed in chunks, its spans the whole life's.

Carried: the last ENC_E2E_LOST page (its count, the latest encoder frame before it and that
frame's sequence number: ``compare.lost_beyond_gaps`` runs on it and the chunk's pages), the
encoder frames counted so far with the last one's sequence number, and whether a summary saying
MAILBOX_OVERFLOW came after the last page (``compare._overflow_reported_after`` per chunk).

The streamed analysis does not place the allowance itself (its per-sample sums of the largest
merge errors): a life with a span is refused (``stream_analysis.NotStreamable``) and analysed
whole; without one the allowance is 0 everywhere, as in the whole log."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.compare import (
    LOST_PAGE,
    _overflow_reported_after,
    heading_steps,
    lost_beyond_gaps,
    merge_errors,
    worst_losses_m,
)
from odocan.host.judge.reference import Geometry, wrap_delta
from odocan.host.judge.samples import Encoders
from odocan.host.protocol.decode import BulkDecoder, DecodeError

FloatArray = npt.NDArray[np.float64]


@dataclass
class StreamLosses:
    """``firmware_losses`` chunk by chunk: ``feed`` each chunk with its accepted mask and
    ``StreamEncoders``' frames, then ``spans``."""

    decoder: BulkDecoder
    _found: list[tuple[int, int, int]] = field(default_factory=list)  # spans between pages
    _offset: int = 0  # frames before the chunk
    _enc_count: int = 0  # accepted encoder frames before the chunk
    _last_seq: int = 0  # the sequence number of the last of them
    _page: tuple[int, int, int] | None = None  # the last page: upto, its seq, lost
    _signal: bool = True  # the DBC's ODOM_STATUS has ENC_E2E_LOST
    _overflow_after: bool = False  # a MAILBOX_OVERFLOW summary after the last page

    def feed(self, chunk: FrameArrays, accepted: npt.NDArray[np.bool_], enc: Encoders) -> None:
        """Take the next chunk (``enc``: its accepted encoder frames, ``index`` in the log)."""
        page = self._page_rows(chunk)
        keep = accepted[page["index"]] if page else np.zeros(0, dtype=bool)
        index = page["index"][keep] if page else np.zeros(0, dtype=np.int64)
        if len(index):
            self._add_pages(index + self._offset, page["ENC_E2E_LOST"][keep].astype(np.int64),
                            enc)
        reported = _overflow_reported_after(chunk, accepted, self.decoder,
                                            int(index[-1]) if len(index) else -1)
        self._overflow_after = reported if len(index) else (self._overflow_after or reported)
        self._offset += len(chunk)
        self._enc_count += len(enc.index)
        if len(enc.seq):
            self._last_seq = int(enc.seq[-1])

    def spans(self) -> list[tuple[int, int, int]]:
        """``firmware_losses`` of the life fed: (first, last, n) per span."""
        n_enc = self._enc_count
        if not self._signal or n_enc < 2:
            return []
        spans = list(self._found)
        tail = self._page[0] if self._page is not None else 0
        if self._overflow_after:
            spans.append((tail, n_enc - 1, n_enc - 1 - tail))
        return spans

    def _add_pages(
        self, index: npt.NDArray[np.int64], lost: npt.NDArray[np.int64], enc: Encoders
    ) -> None:
        """The chunk's pages (``index`` in the log) after the one carried."""
        before = np.searchsorted(enc.index, index)  # the chunk's encoder frames before each
        upto = np.maximum(self._enc_count + before - 1, 0)
        seq = np.where(before > 0, enc.seq[np.maximum(before - 1, 0)] if len(enc.seq)
                       else 0, self._last_seq if self._enc_count else 0)  # (seq[0] is 0)
        if self._page is not None:
            upto, seq, lost = (np.r_[self._page[0], upto], np.r_[self._page[1], seq],
                               np.r_[self._page[2], lost])
        excess = lost_beyond_gaps(lost[:-1], lost[1:], seq[:-1], seq[1:], np.diff(upto))
        self._found += [(int(upto[k]), int(upto[k + 1]), int(excess[k]))
                        for k in np.flatnonzero(excess > 0)]
        self._page = (int(upto[-1]), int(seq[-1]), int(lost[-1]))

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
    """``compare.loss_allowance`` for the spans of a life (``StreamLosses.spans``) from a
    pass over its encoder frames (``feed``) and its kept on-board samples (``named``): each
    frame's ``drop_errors`` from the steps into it and out of it (the heading a continued
    cumulative sum, bit for bit the whole life's), kept only inside the spans; then each
    span's weight (``compare.worst_losses_m``, the frames a sample names excepted) and the
    allowance at any encoder frame (the weights of the spans that began before it, added in
    the same order)."""

    spans: list[tuple[int, int, int]]
    geometry: Geometry
    bits: int
    integrator: str
    _count: int = 0  # encoder frames fed
    _window: tuple[npt.NDArray[np.int64], npt.NDArray[np.int64], FloatArray] | None = None
    _drops: dict[int, float] = field(default_factory=dict)  # frame -> its drop error
    _named: set[int] = field(default_factory=set)  # frames in a span a sample names
    _sums: FloatArray | None = None  # weights added up, span by span

    def feed(self, enc: Encoders) -> None:
        """The life's next accepted encoder frames."""
        if len(enc.index) == 0:
            return
        left, right = enc.left, enc.right
        if self._window is not None:  # the last two frames: left, right, heading
            left, right = np.r_[self._window[0], left], np.r_[self._window[1], right]
        dl = wrap_delta(np.diff(left), self.bits)
        dr = wrap_delta(np.diff(right), self.bits)
        carried = 0 if self._window is None else len(self._window[0])
        new_steps = heading_steps(dl[max(carried - 1, 0):], dr[max(carried - 1, 0):],
                                  self.geometry)
        h_last = 0.0 if self._window is None else float(self._window[2][-1])
        heading = np.cumsum(np.concatenate(([h_last], new_steps)))
        heading = heading if self._window is None else np.r_[self._window[2][:-1], heading]
        first_g = self._count - carried  # the window's first frame
        errors = merge_errors(dl, dr, heading, self.geometry, self.integrator)
        self._keep(first_g + 1 + np.arange(len(errors)), errors)
        self._count += len(enc.index)
        self._window = (left[-2:], right[-2:], heading[-2:])

    def named(self, sample_enc: npt.NDArray[np.int64]) -> None:
        """Kept on-board samples' encoder frames: a frame a sample names was not lost."""
        inside = self._inside(sample_enc)
        self._named.update(sample_enc[inside].tolist())

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
            last = self._count - 1  # the life's last frame (drop 0, as the first)
            weights = []
            for first, stop, n in self.spans:
                drops = np.array([0.0 if g in self._named or g in (0, last)
                                  else self._drops.get(g, 0.0)
                                  for g in range(first, stop + 1)], dtype=np.float64)
                weights.append(worst_losses_m(drops, 0, len(drops) - 1, n))
            total, sums = 0.0, []
            for w in weights:  # loss_allowance's order: 0.0 + w1 + w2 + ...
                total = total + w
                sums.append(total)
            self._sums = np.array(sums, dtype=np.float64)
        return self._sums

    def _inside(self, frames: npt.NDArray[np.int64]) -> npt.NDArray[np.bool_]:
        """Which ``frames`` lie in a span (the spans' firsts and lasts do not go back: the
        latest span begun at or before a frame reaches furthest)."""
        if not self.spans:
            return np.zeros(len(frames), dtype=bool)
        firsts = np.array([s[0] for s in self.spans], dtype=np.int64)
        lasts = np.array([s[1] for s in self.spans], dtype=np.int64)
        k = np.searchsorted(firsts, frames, side="right") - 1
        inside: npt.NDArray[np.bool_] = (k >= 0) & (frames <= lasts[np.maximum(k, 0)])
        return inside

    def _keep(self, frames: npt.NDArray[np.int64], errors: FloatArray) -> None:
        inside = self._inside(frames)
        self._drops.update(zip(frames[inside].tolist(), errors[inside].tolist(), strict=True))
