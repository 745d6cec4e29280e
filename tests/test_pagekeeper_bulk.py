"""The pages a chunk of status frames keeps at once (``pagekeeper.statuses``: the whole-log and
the streamed judge) are the ones its frames fed one at a time keep (``PageKeeper.status``: the
live judge, the definition), in the same order, with the same state carried to the next chunk.

Random status streams (hypothesis): summaries and pages 1..6 interleaved as a firmware sends
them or not (pages without their summary, COUNTER skips, bad CRCs, summaries let out in a burst,
pages late in their tick), split into chunks at random places, against the per-frame keeper.
"""

from __future__ import annotations

import itertools

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from odocan.host.judge.pagekeeper import (
    LOST_PAGE,
    TOTALS_PAGE,
    PageKeeper,
    Status,
    StatusRows,
    statuses,
)

CYCLE_S = 0.01  # WHEEL_ENCODERS' cycle

Frame = tuple[Status, tuple[int, ...] | None]


@st.composite
def streams(draw: st.DrawFn) -> list[Frame]:
    """Status frames in bus order with their page's counts (None: not a counted page)."""
    frames: list[Frame] = []
    t_s, counter, before, last_s, raw = 0.0, 0, 0, -1.0, draw(st.sampled_from([-1, 0]))
    for _ in range(draw(st.integers(0, 60))):
        page = draw(st.sampled_from([0, 0, 0, LOST_PAGE, TOTALS_PAGE, 3, 6]))
        t_s += draw(st.sampled_from([0.0, 0.001, 0.004, 0.006, 0.03, 0.1, 0.1, 0.25]))
        counter = (counter + draw(st.sampled_from([1, 1, 1, 2, 0]))) & 0xF
        if draw(st.booleans()):
            grew = draw(st.integers(0, 12))
            before, raw = before + grew, raw if raw < 0 else raw + grew + draw(st.integers(0, 3))
            last_s = t_s - draw(st.sampled_from([0.0, 0.002, 0.009]))
        crc_ok = draw(st.integers(0, 9)) > 0
        counts: tuple[int, ...] = (draw(st.integers(0, 70_000)), draw(st.integers(0, 300)))
        if page == LOST_PAGE and draw(st.booleans()):  # its refusals (gapchecked) decoded
            counts += (draw(st.integers(0, 0xFFFFFF)),)
        counted = page in (LOST_PAGE, TOTALS_PAGE) and draw(st.integers(0, 9)) > 0
        frames.append(((page, counter, t_s, crc_ok, before, last_s, raw),
                       counts if counted else None))
    return frames


def _rows(frames: list[Frame]) -> StatusRows:
    columns = list(zip(*(f for f, _ in frames), strict=True)) or [()] * 7
    counts = [v or (0, 0) for _, v in frames]
    return StatusRows(
        np.array(columns[0], dtype=np.int64), np.array(columns[1], dtype=np.int64),
        np.array(columns[2], dtype=np.float64), np.array(columns[3], dtype=bool),
        np.array(columns[4], dtype=np.int64), np.array(columns[5], dtype=np.float64),
        np.array([v[0] for v in counts], dtype=np.int64),
        np.array([v[1] for v in counts], dtype=np.int64),
        np.array([v is not None for _, v in frames], dtype=bool),
        np.array(columns[6], dtype=np.int64),
        np.array([v[2] if len(v) > 2 else -1 for v in counts], dtype=np.int64))


def _state(keeper: PageKeeper) -> tuple[object, ...]:
    return (keeper.pages, keeper.totals, keeper._pending, keeper._prev, keeper._summary_s,
            keeper._queued)


@settings(max_examples=400, deadline=None)
@given(streams(), st.lists(st.integers(0, 60), max_size=4), st.booleans())
def test_a_chunk_at_once_keeps_what_its_frames_one_by_one_keep(
        frames: list[Frame], cuts: list[int], singles: bool) -> None:
    """Cut at random places, or into chunks of one frame (``singles``: state carried at
    every boundary)."""
    one_by_one, at_once = PageKeeper(CYCLE_S), PageKeeper(CYCLE_S)
    bounds = (list(range(len(frames) + 1)) if singles
              else [0, *sorted(min(c, len(frames)) for c in cuts), len(frames)])
    for start, end in itertools.pairwise(bounds):
        statuses(at_once, _rows(frames[start:end]))
        for frame, value in frames[start:end]:
            one_by_one.status(frame, value)
        assert _state(at_once) == _state(one_by_one)
    at_once.keep_pending(True)
    one_by_one.keep_pending(True)
    assert at_once.pages == one_by_one.pages
    assert at_once.totals == one_by_one.totals


def test_the_streams_keep_pages_of_both_kinds() -> None:
    """The premise: a firmware's regular stream (a summary, then one page, each 100 ms) keeps
    its pages, so the comparison above is not between two empty lists."""
    frames: list[Frame] = []
    for tick in range(12):  # a summary, its page 2 ms after
        t_s, page = 0.1 * tick, (TOTALS_PAGE, LOST_PAGE)[tick % 2]
        frames += [((0, 2 * tick & 0xF, t_s, True, 10 * tick, t_s, 11 * tick), None),
                   ((page, 2 * tick + 1 & 0xF, t_s + 0.002, True, 10 * tick, t_s, 11 * tick),
                    (tick, 1, tick))]
    keeper = PageKeeper(CYCLE_S)
    statuses(keeper, _rows(frames))
    keeper.keep_pending(True)
    assert len(keeper.pages) == 6
    assert len(keeper.totals) == 6
