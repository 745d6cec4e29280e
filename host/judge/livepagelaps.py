"""The live half of ``host.judge.holepages`` (issue #11, rule 5): the laps a hole of the encoder
frames heard takes beyond the window's numbering, proven by the firmware's ODOM_STATUS pages
heard around it (``livegapseen.LiveSeen``), as the whole-log judge raises a recorder's chunk of
32 k + s periods whose poses' COUNTER came round (``holepages.page_numbered``). The same rule
(``holepages.proven_laps``: the last exact page before the hole and the first after it, one chain,
one hole between, quiet, ENC_E2E_OK grown beyond the periods numbered), on the window's frames
numbered by ``samples.sender_seq`` (the holes of the log told by the pose halves heard). The
live judge asks once its samples after such a hole waited for the pages
(``host.judge.livelaphold``)."""

from __future__ import annotations

import numpy as np

from odocan.host.judge.gapseen import Page
from odocan.host.judge.holepages import GAP_CYCLES, exact_page, proven_laps
from odocan.host.judge.livegapseen import LiveSeen
from odocan.host.judge.livewindow import CYCLE_S, Columns, window_holes
from odocan.host.judge.samples import IntArray, sender_seq


def page_laps(window: Columns, halves: Columns | None, seen: LiveSeen, seq: int) -> int:
    """The laps (16 periods each) the pages kept prove the step into encoder frame ``seq``
    (the tracker's) takes beyond the window's numbering; 0 when none (or unknown)."""
    first = seen.first_seq
    pages = seen.keeper.pages
    if first is None or len(pages) < 2 or not seen.keeper.totals:
        return 0
    seqs = window.col("seq").astype(np.int64)
    k = int(np.searchsorted(seqs, seq)) - 1  # the step into ``seq``
    if k < 0 or k + 1 >= len(seqs) or int(seqs[k + 1]) != seq:
        return 0
    numbered = sender_seq(window.col("counter").astype(np.int64), window.col("t_s"), CYCLE_S,
                          window_holes(window, halves))
    step: IntArray = np.diff(numbered)
    gap = (step > 1) | (np.diff(window.col("t_s")) >= GAP_CYCLES * CYCLE_S)
    placed = [_in_window(page, seqs, first) for page in pages]
    exact = [page for page in placed if page is not None and exact_page(step, gap, page)]
    return proven_laps(step, gap, k, exact, seen.keeper.totals)


def _in_window(page: Page, seqs: IntArray, first: int) -> Page | None:
    """``page`` with its frames lo and hi (the life's) as indices into the window's rows; None
    when lo is not there."""
    lo = int(np.searchsorted(seqs, page[0] + first))
    if lo >= len(seqs) or int(seqs[lo]) != page[0] + first:
        return None
    return (lo, page[1], lo + page[2] - page[0], *page[3:])
