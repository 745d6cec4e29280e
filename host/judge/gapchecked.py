"""The third proof of ``host.judge.gapseen`` (issue #11, rule 5: a PASS must never hide a wrong
pose), "by checked": the firmware's E2E check looked at exactly the encoder frames the log holds
between two pages, however many of them it refused.

gapseen's proofs by OK and by LOST need a quiet window (no frame refused, none dropped), so a
delay that reorders frames (the E2E check refuses a late one as WRONG_SEQUENCE or REPEATED every
few frames) left every gap of such a drive its re-placement allowance: on kobuki seed 703 with
``delay=0.5:100,busoff=1:1`` the bus-off's 1 s silence kept ~850 mm, and a pose raised 10 mm
from its end PASSed.

The evidence: gapseen's pages p, q of one life, each made in its tick (``PageKeeper``), and lo,
hi as gapseen defines them, also counted among every 8-byte WHEEL_ENCODERS frame logged, those
the host's E2E check refused too (``raw_lo``, ``raw_hi``). Every frame on the wire reaches the
firmware's controller (CAN delivers it to every node), which puts it in the mailbox or drops it
(OVERFLOWED_FRAMES counts it); each 8-byte WHEEL_ENCODERS frame taken from the mailbox goes
through the E2E check, which counts it once: accepted (ENC_E2E_OK, OK or OKSOMELOST), REPEATED,
WRONG_SEQ or CRC_ERROR (a frame of another length carries nothing: REJECTED_FRAMES alone counts
it). REJECTED_FRAMES counts every E2E refusal too.

* The FRAME_TOTALS pages a (the last sent before frame lo(p): made before p) and b (the first
  sent at or after q) are joined by kept pages each less than ``WRAP_SAFE_S`` after the one
  before: their u16 counts' growths are exact (``pagechain``). OVERFLOWED_FRAMES did not grow:
  no frame dropped from p to q. REJECTED_FRAMES grew by r.
* The three u8 refusal counts' growths from p to q, each mod 256 (g, summed), are exact when
  r - g < 256: the true growths sum to g + 256 w (w the wraps) and to at most r (each refusal
  counts in REJECTED too, and a .. b holds p .. q), so w = 0. (It asked r < 256 before: the
  FRAME_TOTALS pages a, b lie far beyond p, q when the delay held pages back, and the refusals
  counted there pushed r past 255 where g was exact: pmir straight seed 411,
  ``delay=0.4:70,busoff=3:0.4``, r = 274 and g = 185 around the 0.4 s bus-off, whose silence
  then kept gapbound's 1886 mm and absorbed a pose raised 10 mm from its end. The brief's
  stricter rule, r equal to their sum, never held on a delayed drive: a .. b reaches beyond p ..
  q, where the delay goes on refusing frames. A refusal of another kind changes no encoder frame
  the firmware took: an implausible step is one of the log's frames accepted by E2E and not
  integrated, which the judge's re-prime model follows as anywhere else.)
* N, ENC_E2E_OK's growth (one chain: exact) plus the refusals', counts every encoder frame the
  firmware received from p to q. Every frame logged from raw_hi(p) (after p was made) to
  raw_lo(q) (before q was made) was on the wire then, so N >= raw_lo(q) - raw_hi(p) + 1. If N
  equals it the firmware received those frames and no other: none the log lacks. ENC_E2E_OK's
  growth must equal the frames the host accepted there (lo(q) - hi(p) + 1): the host's E2E
  check is the firmware's on the same frames. Where it chose otherwise the proof could only make
  the judge FAIL a correct firmware, never PASS a wrong one: it withdraws allowances.
* As many is not the same ones: the host's window is never narrower than the firmware's
  (``e2e_periods.receive_periods``), so after a frame held back over a silence it can take a
  frame the firmware refused and then refuse one the firmware took, the counts equal. ENC_E2E_LOST
  tells (each accepted frame adds its COUNTER advance less one: over the same frames from the
  same last one, the same sum; over others, a whole COUNTER cycle apart): its growth mod 256
  must equal the host's over its frames from lo(p) to lo(q) (``LostPages.host_lost``). kobuki
  random ``--seed 444 --faults reboot=2:0.4,delay=0.3:55,busoff=7:0.2``: after the bus-off the
  host took COUNTER 1 and 3 (7.265, 7.285 s), the firmware refused them and took COUNTER 11
  (7.31 s), one frame fewer near there and one more elsewhere; the window from 3.1 to 8.5 s was
  proven, the gap into COUNTER 1 earned no allowance, and the firmware's merged step over the
  bus-off, 0.44 mm off the reference's steps, FAILed a correct firmware (issue #11).

A frame near a page's tick (on the wire between the summary and its page, or taken by the
firmware only at the next tick) lies outside raw_hi(p) .. raw_lo(q) or makes N differ: the window
is not proven, never wrongly proven. A frame the log lacks that the firmware received makes N
exceed the count, refused or not; one dropped from the mailbox moves OVERFLOWED; 256 refusals
wrap a u8 count but not REJECTED: each keeps the allowance (``tests/test_gap_checked.py``). The
windows proven join gapseen's others (``Seen.same``, ``Seen.counted``: ``took_across``): a gap
inside took no frame the log lacks, whatever the COUNTER did (a re-prime), as by OK.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import numpy.typing as npt

from odocan.host.judge.pagechain import U16, WRAP_SAFE_S
from odocan.host.judge.samples import FloatArray, IntArray

U8 = 0xFF
UNKNOWN = -1  # an ENC_E2E page whose refusals are not known (the boot's, a judge without them)
REFUSED = ("ENC_E2E_REPEATED", "ENC_E2E_CRC_ERROR", "ENC_E2E_WRONG_SEQ")  # u8 counts
Bools = npt.NDArray[np.bool_]

if TYPE_CHECKING:
    from odocan.host.judge.gapseen import LostPages, TotalsPages


def packed(repeated: int, crc_error: int, wrong_seq: int) -> int:
    """An ENC_E2E page's three u8 refusal counts (``REFUSED``) in one int."""
    return (repeated & U8) | (crc_error & U8) << 8 | (wrong_seq & U8) << 16


def packed_rows(repeated: IntArray, crc_error: IntArray, wrong_seq: IntArray) -> IntArray:
    """``packed`` of pages column by column."""
    rows: IntArray = (repeated & U8) | (crc_error & U8) << 8 | (wrong_seq & U8) << 16
    return rows


def refused_growth(refused_p: IntArray, refused_q: IntArray) -> IntArray:
    """Per pair: the sum of the three u8 counts' growths, each mod 256 (``packed``)."""
    grew = np.zeros(len(refused_p), dtype=np.int64)
    for k in range(3):
        grew += ((refused_q >> 8 * k) - (refused_p >> 8 * k)) & U8
    return grew


def totals_growth(sent_s: FloatArray, counts: IntArray, from_s: FloatArray, to_s: FloatArray
                  ) -> tuple[Bools, IntArray]:
    """Per window: whether the last FRAME_TOTALS page sent before ``from_s`` and the first at or
    after ``to_s`` exist and are joined by steps each < ``WRAP_SAFE_S``, and the u16
    ``counts``' exact growth between them (0 where not)."""
    n = len(sent_s)
    if n == 0:
        return np.zeros(len(from_s), dtype=bool), np.zeros(len(from_s), dtype=np.int64)
    unwrapped = np.concatenate(([0], np.cumsum(np.diff(counts) & U16)))
    chain = np.concatenate(([0], np.cumsum(np.diff(sent_s) >= WRAP_SAFE_S)))
    a = np.searchsorted(sent_s, from_s, side="left") - 1
    b = np.searchsorted(sent_s, to_s, side="left")
    have = (a >= 0) & (b < n)
    a, b = np.maximum(a, 0), np.minimum(b, n - 1)
    joined: Bools = have & (chain[a] == chain[b])
    return joined, np.where(joined, unwrapped[b] - unwrapped[a], 0)


def by_checked(pages: LostPages, totals: TotalsPages, i: IntArray, j: IntArray) -> Bools:
    """Per pair of pages (i, j) of one life: whether the firmware received exactly the log's
    encoder frames between them (module docstring)."""
    received, ok, sure = _received_logged(pages, totals, i, j)
    proven: Bools = received & (sure > 0) & (ok == sure)
    if pages.host_lost is not None:  # the same frames, not only as many (module docstring)
        proven &= ((pages.lost[j] - pages.lost[i]) & U8) == (
            (pages.host_lost[j] - pages.host_lost[i]) & U8)
    return proven


def by_received(pages: LostPages, totals: TotalsPages, i: IntArray, j: IntArray) -> Bools:
    """Per pair of pages (i, j) of one life: whether the firmware received exactly the log's
    encoder frames between them, however many of them it accepted (``gapreceived``)."""
    return _received_logged(pages, totals, i, j)[0]


def skipped_frames(pages: LostPages, totals: TotalsPages, i: IntArray, j: IntArray) -> IntArray:
    """Per pair of pages (i, j): how many of the log's encoder frames between them the firmware
    refused, where it received exactly the log's frames there, every one of which the host
    accepted (the log holds no frame the host refused: ``raw_sure`` equals ``sure``), and
    accepted fewer than the host (``ok < sure``); -1 elsewhere. Its accepted frames there are
    then the host's less that many (``gapseen.Seen.skips``)."""
    received, ok, sure = _received_logged(pages, totals, i, j)
    raw_sure = pages.raw_lo[j] - pages.raw_hi[i] + 1
    fewer = received & (sure > 0) & (raw_sure == sure) & (ok < sure)
    out: IntArray = np.where(fewer, sure - ok, -1)
    return out


def _received_logged(pages: LostPages, totals: TotalsPages, i: IntArray, j: IntArray
                     ) -> tuple[Bools, IntArray, IntArray]:
    """Per pair of pages: whether the firmware received exactly the encoder frames logged
    between them (N = OK's growth plus the refusals' equals raw_lo(q) - raw_hi(p) + 1, nothing
    dropped, the u8 counts exact: module docstring), OK's growth and lo(q) - hi(p) + 1."""
    known = (pages.refused[i] >= 0) & (pages.refused[j] >= 0)
    joined, overflowed = totals_growth(totals.sent_s, totals.overflowed, pages.lo_s[i],
                                       pages.sent_s[j])
    _, rejected = totals_growth(totals.sent_s, totals.rejected, pages.lo_s[i], pages.sent_s[j])
    refused = refused_growth(pages.refused[i], pages.refused[j])
    ok = pages.ok_u[j] - pages.ok_u[i]
    sure = pages.lo[j] - pages.hi[i] + 1
    raw_sure = pages.raw_lo[j] - pages.raw_hi[i] + 1
    received: Bools = (known & joined & (overflowed == 0) & (rejected - refused <= U8)
                       & (rejected >= refused) & (pages.chain[i] == pages.chain[j])
                       & (ok + refused == raw_sure))
    return received, ok, sure
