"""The firmware's ODOM_STATUS counts chained page to page across a span of any length (issue #11,
rule 5: a PASS must never hide a wrong pose), for ``host.judge.gapseen``.

A u16 count (ENC_E2E_OK, REJECTED_FRAMES, OVERFLOWED_FRAMES) read on two pages less than
``WRAP_SAFE_S`` apart grew by exactly its difference mod 65536: 65536 frames cannot pass on a
1 Mbit/s bus (at most ~9 000 frames/s) in that time, and the firmware accepts, refuses or drops
only frames that were on the bus. So over pages p_0, p_1, ..., p_m of one life, each less than
``WRAP_SAFE_S`` after the one before (a "chain"), the sum of those differences is the exact
growth from p_0 to p_m, however long the span: the span itself needs no bound on its frames,
each step does. ``gapseen`` paired pages only less than 7 s apart, so a bus silence of the
encoder sender longer than that (``--faults busoff=5:30``: the motor controller off the bus for
10.8 s) kept ``gapbound``'s worst-case allowance (21.78 m on a kobuki: 10 m of X added after the
silence PASSed), although the pages heard all through it show the firmware took no frame there.

* ENC_E2E_OK: each kept page carries its count unwrapped along the chain (``chained_ok``) and the
  chain's number; two pages of one chain have the exact count of frames accepted between them.
* REJECTED / OVERFLOWED: each kept FRAME_TOTALS page carries the number of "breaks" before it
  (``chained_breaks``: a step of ``WRAP_SAFE_S`` or more, or a step whose counts differ). Two
  pages with the same number of breaks are joined by steps each < ``WRAP_SAFE_S`` with no
  difference: no frame was refused or dropped between them (``quiet``).
* A long silence (``long_pairs``): per gap of the log, the last page made before its frame
  before and the first made after its frame after, however many pages lie between, are a pair
  ``gapseen`` checks as any other (a pair of pages within ``PAIR_PAGES`` covers short gaps).

A page missed (the recorder lost it) only lengthens a step: a step of ``WRAP_SAFE_S`` or more
starts a new chain (no evidence across it). Nothing else changes in ``gapseen``'s proof.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from odocan.host.judge.samples import FloatArray, IntArray

WRAP_SAFE_S = 7.0  # 65536 frames take longer than this on a 1 Mbit/s bus (~9 000 frames/s)
U16 = 0xFFFF


def chained_ok(prev: tuple[int, int, float] | None, ok: int, sent_s: float) -> tuple[int, int]:
    """(ENC_E2E_OK unwrapped, chain number) of a page sent at ``sent_s`` after the last page
    kept (``prev``: its unwrapped count, chain, time; None: the life's first)."""
    if prev is None:
        return ok, 0
    ok_u, chain, prev_s = prev
    if sent_s - prev_s >= WRAP_SAFE_S:
        return ok, chain + 1
    return ok_u + ((ok - ok_u) & U16), chain


def chained_breaks(prev: tuple[float, int, int, int] | None, sent_s: float, rejected: int,
                   overflowed: int) -> int:
    """The breaks before a FRAME_TOTALS page (``prev``: the last kept, sent_s, REJECTED,
    OVERFLOWED, its breaks; None: the life's first, no break before it)."""
    if prev is None:
        return 0
    prev_s, prev_rejected, prev_overflowed, breaks = prev
    moved = prev_rejected != rejected or prev_overflowed != overflowed
    return breaks + int(moved or sent_s - prev_s >= WRAP_SAFE_S)


def boot_ok(first: tuple[int, int, int, float], boot_s: float) -> tuple[int, int]:
    """(unwrapped count, chain) of the power-up's page (every count 0) before the first page
    (``first``: its raw ENC_E2E_OK, unwrapped count, chain, time)."""
    ok, ok_u, chain, sent_s = first
    if sent_s - boot_s >= WRAP_SAFE_S:
        return 0, chain - 1
    return ok_u - (ok & U16), chain


def boot_breaks(first: tuple[float, int, int, int], boot_s: float) -> int:
    """The breaks before the power-up's FRAME_TOTALS page (counts 0) put before ``first``
    (sent_s, REJECTED, OVERFLOWED, breaks): one fewer when the step to it is a break."""
    sent_s, rejected, overflowed, breaks = first
    return breaks - int(rejected != 0 or overflowed != 0 or sent_s - boot_s >= WRAP_SAFE_S)


def quiet(sent_s: FloatArray, breaks: IntArray, from_s: FloatArray, to_s: FloatArray
          ) -> npt.NDArray[np.bool_]:
    """Per window: the last FRAME_TOTALS page sent before ``from_s`` and the first at or after
    ``to_s`` exist and no break lies between them (no frame refused or dropped between)."""
    a = np.searchsorted(sent_s, from_s, side="left") - 1
    b = np.searchsorted(sent_s, to_s, side="left")
    n = len(sent_s)
    have = (a >= 0) & (b < n)
    a, b = np.maximum(a, 0), np.minimum(b, n - 1)
    same: npt.NDArray[np.bool_] = have & (breaks[a] == breaks[b])
    return same


def long_pairs(lo: IntArray, hi: IntArray, gap_frames: IntArray, apart: int
               ) -> tuple[IntArray, IntArray]:
    """Pairs of pages (i, j) more than ``apart`` pages apart, one per gap of the log (its frame
    after in ``gap_frames``): i the last page made before the gap's frame before (hi(i) at most
    it), j the first made after its frame after (lo(j) at least it)."""
    i = np.searchsorted(hi, gap_frames - 1, side="right") - 1
    j = np.searchsorted(lo, gap_frames, side="left")
    keep = (i >= 0) & (j < len(lo)) & (j - i > apart)
    pairs = np.unique(np.stack((i[keep], j[keep])), axis=1)
    return pairs[0].astype(np.int64), pairs[1].astype(np.int64)
