"""Skip proofs of the poses that the firmware's own count of the frames it took contradicts
(issue #11: a FAIL must never blame a correct firmware; ``host.protocol.e2e_evidence``).

A pose's ENC_COUNTER held over two sends proves the frames between not integrated
(``pose_evidence``'s ``skipped``), which ``settle`` reads as refused by the E2E check. The
firmware also leaves the name held on a frame its E2E check took and its plausibility bound
refused (``e2e_implausible``): such a frame moves the check's last COUNTER on, and the frames
on time after it are refused. Under ``delay`` that is a frame held back 150 ms: it comes as
the next in the sequence, 15 periods of motion behind, and is refused by the bound; the
frames after it are E2E-checked against it. On kobuki random, seed 710,
``busoff=1.5:0.4,delay=0.2:150,reboot=4.0:0.2``, the late COUNTER 7 and 9 at 7.26 and 7.28 s
were taken by the firmware's E2E check and refused by the bound (the 7.26 s on-time 6 named
held), and three refusals in a row re-primed it on the late stream (COUNTER_RESET at 7.26 s
and 7.37 s); the host read both as E2E skips, took the on-time 8, 9, 12, 13, 14 instead,
saw no re-prime there, and FAILed the correct firmware by 2.34 mm and 107 mrad.

The firmware counts what its E2E check took (ENC_E2E_OK, ``e2e_pages``). Where, between two
such pages, the stamps' strict reading takes exactly the firmware's count and the verdicts
settled by the poses do not, the skip proofs in that span are dropped and the message judged
again; the new verdicts are kept only where every span they changed comes to the firmware's
count (a span that agreed never leaves it), else the settled ones stand.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

import numpy as np
import numpy.typing as npt

from odocan.host.protocol.e2e_evidence import S_LOST, S_OK, Evidence
from odocan.host.protocol.e2e_pages import U16_MASK, OkPages

IntArray = npt.NDArray[np.int64]

Statuses = npt.NDArray[np.int8]
SettleWith = Callable[[Evidence], Statuses]


def exact_surplus(enc_pos: npt.NDArray[np.intp], status: Statuses, pages: OkPages) -> IntArray:
    """Per span between two consecutive pages: the encoder frames (at bus positions
    ``enc_pos``, judged ``status``) the host took on the bus between them beyond the
    firmware's count (negative: too few); no race allowed (``e2e_pages.surplus`` allows a frame
    drained after its page: here a count met exactly is the proof), 0 where the pages prove
    nothing (a reboot, a wrapped count)."""
    if len(pages.at) < 2:
        return np.zeros(0, dtype=np.int64)
    taken = ((status == S_OK) | (status == S_LOST)).astype(np.int64)
    cum = np.concatenate([np.zeros(1, dtype=np.int64), np.cumsum(taken)])
    before = np.searchsorted(enc_pos, pages.at)
    firmware = np.diff(pages.ok) & U16_MASK
    result: IntArray = (np.diff(cum[before]) - firmware).astype(np.int64)
    result[firmware > np.diff(before)] = 0
    return result


def contradicted_skips(enc_pos: npt.NDArray[np.intp], settled: Statuses, strict: Statuses,
                       evidence: Evidence, pages: OkPages) -> frozenset[int]:
    """The skip proofs (indices into the message's frames at bus positions ``enc_pos``) in the
    spans between pages where ``strict`` meets the firmware's count exactly and ``settled`` does
    not (``exact_surplus``)."""
    off = np.flatnonzero((exact_surplus(enc_pos, settled, pages) != 0)
                         & (exact_surplus(enc_pos, strict, pages) == 0))
    if len(off) == 0:
        return frozenset()
    bounds = np.searchsorted(enc_pos, pages.at).tolist()
    spans = [(bounds[s], bounds[s + 1]) for s in off.tolist()]
    return frozenset(j for j in evidence.skipped if any(lo <= j < hi for lo, hi in spans))


def by_page_skips(run_with: SettleWith, settled: Statuses, strict: Statuses,
                  enc_pos: npt.NDArray[np.intp], evidence: Evidence,
                  pages: OkPages | None) -> Statuses:
    """``settled``, or the verdicts of ``run_with`` (``settle`` with other evidence) without the
    skip proofs the pages contradict, where those bring every span they change to the
    firmware's count (module docstring)."""
    if pages is None or not evidence.skipped:
        return settled
    dropped = contradicted_skips(enc_pos, settled, strict, evidence, pages)
    if not dropped:
        return settled
    trial = run_with(replace(evidence, skipped=evidence.skipped - dropped))
    before, after = (exact_surplus(enc_pos, settled, pages),
                     exact_surplus(enc_pos, trial, pages))
    changed = after != before
    if changed.any() and not (after[changed] != 0).any():
        return trial
    return settled
