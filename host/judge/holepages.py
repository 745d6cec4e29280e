"""Holes of the log numbered by the firmware's own count of the encoder frames it took (issue
#11, rule 5: a FAIL must never blame a correct firmware).

``senderseq.sender_seq`` numbers a hole of the log by its stamps, and the first frame after a
recorder's chunk, read in a burst, by the least late frame of the burst (``burst_laps``) when
the poses' COUNTER shows the chunk (``pose_skips``). A chunk of 32 k + s periods (s small)
takes 16 k poses and brings their COUNTER round: the burst is read as a busy bus's and the
hole numbered 32 k periods short (a correct pmir drive holed 33 periods FAILed; 65 likewise).

The firmware's ODOM_STATUS pages span the hole with evidence of their own: ENC_E2E_OK, the
encoder frames it accepted (``gapseen.PageKeeper``: only pages made in their tick, chained by
``pagechain.chained_ok``). For the last such page p before a hole and the first q after it, of
one chain, let S_p, S_q be the sender's numbers of the last encoder frames the firmware had when
it made them. When the log's frames around p are lo(p) and hi(p) = lo(p) + 1 one period apart
(``gapseen``: the firmware had lo(p), not hi(p)), S_p = seq(lo(p)) exactly; likewise S_q. The
firmware accepted g = OK(q) - OK(p) frames of (S_p, S_q]. Only where ENC_E2E_LOST did not grow
and FRAME_TOTALS shows no frame refused or dropped between (``pagechain.quiet``: a forger's
frame whose CRC holds would count in OK, but its others are refused) are the counts read: then
S_q - S_p >= g, and a hole numbered shorter is raised by the fewest COUNTER laps (16) that meet
it. A hole numbered longer is never lowered: a stalled sender's hole spans more periods than
the frames it sent (its COUNTER goes on by one), so S_q - S_p = g says nothing of the periods
(a firmware that lost 16 k + 1 frames on the bus saw no skip either). Only a span with one
step where the log lacks frames or its stamps may hide a lap
(``GAP_CYCLES``) is numbered so (the laps of two holes cannot be shared out by one count); the
hole's COUNTER step (mod 16) stays what it is. The live judge, whose pages after a hole come
0.6 s after it, holds its samples after such a hole for them and applies the same rule on its
window (``livelaphold``, ``livepagelaps``).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays
from odocan.host.judge.gapseen import Page, PageEvidence, Totals
from odocan.host.judge.pagechain import quiet
from odocan.host.judge.samples import Encoders, IntArray
from odocan.host.protocol.busfacts import ENC_COUNTER_LAP
from odocan.host.protocol.decode import BulkDecoder

LAP = ENC_COUNTER_LAP  # the encoder COUNTER's lap: a hole's numbering is known but for whole laps
U8 = 0xFF
GAP_CYCLES = LAP // 2  # a step of the stamps this long may hide a lap: a recorder's stamps
# are late, never early, the frame before a hole up to 8 periods (``burst_laps``)


def page_numbered(frames: FrameArrays, decoder: BulkDecoder, enc: Encoders) -> Encoders:
    """``enc`` with each hole the firmware's pages span renumbered (module docstring)."""
    if enc.cycle_s is None or len(enc.seq) < 3:
        return enc
    step: IntArray = np.diff(enc.seq)
    gap = (step > 1) | (np.diff(enc.timestamp_s) >= GAP_CYCLES * enc.cycle_s)
    if not gap.any():  # no hole: the pages need not be read
        return enc
    evidence = PageEvidence(decoder)
    evidence.feed(frames, enc)
    evidence.keeper.keep_pending(True)
    pages = [p for p in evidence.keeper.pages if exact_page(step, gap, p)]
    changed = False
    for k in np.flatnonzero(gap).tolist():
        laps = proven_laps(step, gap, k, pages, evidence.keeper.totals)
        if laps:
            step[k] += LAP * laps
            changed = True
    if not changed:
        return enc
    seq: IntArray = np.concatenate(([enc.seq[0]], enc.seq[0] + np.cumsum(step)))
    return replace(enc, seq=seq)


def proven_laps(step: IntArray, gap: npt.NDArray[np.bool_], k: int, pages: list[Page],
          totals: list[Totals]) -> int:
    """The laps to add to step ``k`` (a hole of the log) that the last page before it and the
    first after it prove (0: none)."""
    before = [p for p in pages if p[0] < k]
    after = [q for q in pages if q[0] > k]
    if not before or not after:
        return 0
    p, q = before[-1], after[0]
    if p[7] != q[7] or int(np.count_nonzero(gap[p[0]:q[0]])) != 1:
        return 0
    took = q[6] - p[6]  # ENC_E2E_OK's growth along the chain: frames accepted in (S_p, S_q]
    span = int(np.sum(step[p[0]:q[0]]))
    if not _all_seen(p, q, totals):  # a forgery accepted would count too (REJECTED tells)
        return 0
    if span < took:
        return -((span - took) // LAP)  # the fewest laps that meet the count
    return 0  # never lowered: a stalled sender's hole spans more periods than frames it sent


def exact_page(step: IntArray, gap: npt.NDArray[np.bool_], page: Page) -> bool:
    """Whether the sender's number of the last frame the firmware had when it made ``page`` is
    known: its frames before and after are one period apart, no hole between."""
    lo, hi = page[0], page[2]
    return 0 <= lo < len(step) and hi == lo + 1 and int(step[lo]) == 1 and not gap[lo]

def _all_seen(p: Page, q: Page, totals: list[Totals]) -> bool:
    """Whether, from ``p`` to ``q``, ENC_E2E_LOST did not grow and no frame was refused or
    dropped (``pagechain.quiet``)."""
    if (q[4] - p[4]) & U8 or not totals:
        return False
    sent_s = np.array([t[0] for t in totals], dtype=np.float64)
    breaks = np.array([t[3] for t in totals], dtype=np.int64)
    return bool(quiet(sent_s, breaks, np.array([p[1]]), np.array([q[5]]))[0])
