"""The ODOM_STATUS pages a firmware made in their tick (``host.judge.gapseen``'s evidence), kept
from its status frames in bus order: one frame at a time (``PageKeeper.status``: the live judge)
or a chunk at once (``PageKeeper.statuses``: the whole-log and the streamed judge, the same pages
kept and the same state after; an hour's 28 000 summaries one by one were 0.24 of analyze's 1.3 s).

A page counts when it came right after its tick's summary (CRC good, COUNTER one more, within
half an encoder cycle), the summary on time: not within ``QUEUED_GAP_CYCLES`` of the summary
before (both let out in a burst). Its tick's pages wait for the next summary: kept unless that
one came close (the two in a burst), or at the end of the log."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TypeVar

import numpy as np
import numpy.typing as npt

from odocan.host.judge.pagechain import chained_breaks, chained_ok
from odocan.host.judge.samples import QUEUED_GAP_CYCLES, FloatArray, IntArray
from odocan.host.protocol import busfacts
from odocan.host.protocol.busfacts import ENC_COUNTER_MASK

LOST_PAGE = busfacts.ENC_E2E_PAGE  # ODOM_STATUS page with ENC_E2E_OK and ENC_E2E_LOST
TOTALS_PAGE = busfacts.TOTALS_PAGE  # ODOM_STATUS page with REJECTED_FRAMES and OVERFLOWED_FRAMES
G = TypeVar("G", bound=np.generic)
Status = tuple[int, int, float, bool, int, float, int]  # a status frame: page, COUNTER, time,
# CRC good, encoder frames before it, the last one's time, every encoder frame logged before it
# (refused by the host's E2E check too: ``gapchecked``; -1: not counted)


Page = tuple[int, float, int, int, int, float, int, int, int, int, int]  # lo, lo_s, hi,
# ENC_E2E_OK, LOST, sent_s, OK unwrapped and its chain (``pagechain.chained_ok``), then lo and
# hi among every encoder frame logged and the E2E refusals (``gapchecked.REFUSED``; -1: unknown)
Totals = tuple[float, int, int, int]  # sent_s, REJECTED_FRAMES, OVERFLOWED_FRAMES, breaks


@dataclass
class PageKeeper:
    """The pages made with their tick's summary (module docstring), kept from status frames
    fed one at a time in bus order: the core of the whole-log, streamed and live evidence."""

    cycle_s: float | None = None  # WHEEL_ENCODERS' cycle time
    pages: list[Page] = field(default_factory=list)  # ENC_E2E pages kept, in bus order
    totals: list[Totals] = field(default_factory=list)  # FRAME_TOTALS pages kept
    _prev: Status | None = None  # the last status frame
    _summary_s: float = -math.inf  # the last summary whose CRC holds: its time
    _queued: bool = False  # and whether it came within QUEUED_GAP_CYCLES of the one before
    _pending: list[tuple[int, tuple[int | float, ...]]] = field(default_factory=list)
    # pages made with the last summary, kept when the next one is not close (or at the end)

    def status(self, frame: Status, value: tuple[int, ...] | None) -> None:
        """One ODOM_STATUS frame (``Status``) and its page's counts (None: not decoded): two, and
        on an ENC_E2E page its refusals packed (``gapchecked.packed``) when decoded."""
        prev, self._prev = self._prev, frame
        if frame[0] == 0 and frame[3]:
            self._summary(frame[2])
        if prev is None or value is None or not self._made_in_tick(prev, frame):
            return
        a, b = value[0], value[1]
        if frame[0] == LOST_PAGE and prev[4] > 0:  # a frame before its summary: S_p known
            refused = value[2] if len(value) > 2 and prev[6] >= 0 <= frame[6] else -1
            self._pending.append((LOST_PAGE, (prev[4] - 1, prev[5], frame[4], a, b, frame[2],
                                              prev[6] - 1, frame[6], refused)))
        elif frame[0] == TOTALS_PAGE:
            self._pending.append((TOTALS_PAGE, (frame[2], a, b)))

    def new_life(self) -> PageKeeper:
        """A keeper for a new firmware life whose first frame (a summary) was the last fed."""
        keeper = PageKeeper(self.cycle_s, _prev=self._prev, _summary_s=self._summary_s)
        return keeper

    def _summary(self, sent_s: float) -> None:
        """A summary whose CRC holds, sent at ``sent_s``: the pages pending on the one before
        it are kept unless this one came within ``QUEUED_GAP_CYCLES`` of it (both let out in a
        burst: ``queued_frames``); its own pages wait for the next."""
        assert self.cycle_s is not None
        close = sent_s - self._summary_s < QUEUED_GAP_CYCLES * self.cycle_s
        self.keep_pending(not close)
        self._queued = close
        self._summary_s = sent_s

    def keep_pending(self, keep: bool) -> None:
        """The pages pending on the last summary kept (``keep``) or dropped."""
        for kind, row in self._pending if keep else []:
            self._keep(kind, row)
        self._pending = []

    def _keep(self, kind: int, row: tuple[int | float, ...]) -> None:
        """A page kept: chained to the last kept of its kind (``pagechain``)."""
        if kind == LOST_PAGE:
            last = self.pages[-1] if self.pages else None
            ok_u, chain = chained_ok(None if last is None else (last[6], last[7], last[5]),
                                     int(row[3]), float(row[5]))
            self.pages.append((*row[:6], ok_u, chain, *row[6:]))  # type: ignore[arg-type]
        else:
            t = self.totals[-1] if self.totals else None
            breaks = chained_breaks(None if t is None else t, float(row[0]), int(row[1]),
                                    int(row[2]))
            self.totals.append((*row, breaks))  # type: ignore[arg-type]

    def _made_in_tick(self, summary: Status, page: Status) -> bool:
        """Whether ``page`` came right after its tick's ``summary`` (module docstring; the
        summary on time so far: not within ``QUEUED_GAP_CYCLES`` of the summary before)."""
        assert self.cycle_s is not None
        return (summary[0] == 0 and summary[3] and not self._queued and page[3]
                and page[0] != 0 and page[1] == (summary[1] + 1) & ENC_COUNTER_MASK
                and page[2] - summary[2] < 0.5 * self.cycle_s)


@dataclass(frozen=True)
class StatusRows:
    """A chunk's status frames in bus order, column by column (``Status``'s fields), and their
    page's counts (``counted``: the page is one whose counts were decoded; ``refused``: an
    ENC_E2E page's refusals packed, -1 unknown)."""

    page: IntArray
    counter: IntArray
    t_s: FloatArray
    crc_ok: npt.NDArray[np.bool_]
    before: IntArray  # encoder frames before it (in the life)
    last_s: FloatArray  # the last one's time
    a: IntArray
    b: IntArray
    counted: npt.NDArray[np.bool_]
    raw_before: IntArray  # every encoder frame logged before it (in the life)
    refused: IntArray


def _after(first: object, column: npt.NDArray[G]) -> npt.NDArray[G]:
    """Each frame's predecessor's value: ``first`` (the carried frame's), then ``column``
    shifted by one."""
    return np.concatenate((np.array([first], dtype=column.dtype), column[:-1]))


def statuses(keeper: PageKeeper, rows: StatusRows) -> None:
    """``keeper.status`` of every frame of ``rows`` in turn, at once: the same pages kept, in
    the same order, and the same state after (``tests/test_pagekeeper_bulk.py``)."""
    n = len(rows.page)
    if n == 0:
        return
    assert keeper.cycle_s is not None
    prev = keeper._prev
    summary = (rows.page == 0) & rows.crc_ok
    at = np.flatnonzero(summary)  # the summaries whose CRC holds
    sent = rows.t_s[at]
    close = sent - np.concatenate(([keeper._summary_s], sent[:-1])) < (
        QUEUED_GAP_CYCLES * keeper.cycle_s)
    last = np.cumsum(summary) - 1  # per frame: the last such summary at or before it
    queued = np.where(last >= 0, close[np.maximum(last, 0)] if len(at) else False,
                      keeper._queued)  # ``_queued`` after each frame
    p = prev if prev is not None else (-1, -1, 0.0, False, 0, 0.0, -1)
    made = (_after(prev is not None and p[0] == 0 and p[3], summary)
            & ~_after(keeper._queued, queued) & rows.crc_ok & (rows.page != 0) & rows.counted
            & (rows.counter == (_after(p[1], rows.counter) + 1) & ENC_COUNTER_MASK)
            & (rows.t_s - _after(p[2], rows.t_s) < 0.5 * keeper.cycle_s))
    p_before, p_last_s = _after(p[4], rows.before), _after(p[5], rows.last_s)
    p_raw = _after(p[6], rows.raw_before)
    refused = np.where((p_raw >= 0) & (rows.raw_before >= 0), rows.refused, -1)
    made &= ((rows.page == LOST_PAGE) & (p_before > 0)) | (rows.page == TOTALS_PAGE)
    pages = np.flatnonzero(made)
    decided = np.searchsorted(at, pages)  # the next summary (a page is none)
    if len(at):  # the pages pending before the chunk: decided by its first summary
        keeper.keep_pending(not bool(close[0]))
    waits = decided == len(at)  # no summary after it in the chunk: still pending
    keeps = waits | ~close[np.minimum(decided, len(at) - 1)] if len(at) else waits
    for kind, lo, lo_s, hi, a, b, t_s, raw_lo, raw_hi, c, wait, keep in zip(
            *(column[pages].tolist() for column in (
                rows.page, p_before - 1, p_last_s, rows.before, rows.a, rows.b, rows.t_s,
                p_raw - 1, rows.raw_before, refused)),
            waits.tolist(), keeps.tolist(), strict=True):
        if keep:
            row = ((lo, lo_s, hi, a, b, t_s, raw_lo, raw_hi, c) if kind == LOST_PAGE
                   else (t_s, a, b))
            if wait:
                keeper._pending.append((kind, row))
            else:
                keeper._keep(kind, row)
    keeper._prev = (int(rows.page[-1]), int(rows.counter[-1]), float(rows.t_s[-1]),
                    bool(rows.crc_ok[-1]), int(rows.before[-1]), float(rows.last_s[-1]),
                    int(rows.raw_before[-1]))
    if len(at):
        keeper._summary_s, keeper._queued = float(sent[-1]), bool(close[-1])
