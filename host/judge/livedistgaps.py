"""The live DISTANCE judge's gaps held for the firmware's pages (issue #11, rule 5: a PASS must
never hide a wrong pose; one judge: ``host.judge.distance``'s ``took_none`` rule, live).

``analyze`` lets the firmware's path grow above the reference's merged step at a gap of the
encoder sequence by the gap's path bound (``distance.gap_extra_m``: it may have taken the gap's
frames one by one), except where the pages prove it took none of them (``gapskips.took_none``).
The live judge (``host.judge.livedistance``) added the bound at every gap and nothing lowered
it: a DISTANCE 10 mm high from a bus-off's end (kobuki seed 24, ``busoff=4:0.3``: 181.8 mm
allowed) PASSed live where ``analyze`` FAILed it by 9.99 mm.

The proof comes a page rotation or two after the gap (the first window over it: an ENC_E2E page
after it, and a FRAME_TOTALS page after that one, ``LiveSeen.told_after``), and the twists
judged before it cannot be judged again (``distance.Feasible`` carries one interval). So the
twists naming the gap's frame or a later one wait, as ``host.judge.livechoice`` holds a choice,
until the gap is decided: proven (its bound withdrawn from every twist after it), told and not
proven, ``HOLD_FRAMES`` of frames later, or the watch or the life ends (its bound kept). The
DISTANCE verdict lags such a gap by at most ``HOLD_FRAMES`` (4.2 s); bounded: ``KEPT_GAPS``
gaps held (more: the oldest decided with its bound).

``HOLD_FRAMES`` was 3 page rotations (180 frames): under ``stall=2:0.05,delay=0.1:30`` (seed
10, pmir figure8 and kobuki random) the ENC_E2E pages of 6.181 and 6.781 s came 30 ms after
their summary (the delay), past ``PageKeeper``'s half cycle, so no page was kept from 5.551 to
7.25 s and the gaps from encoder frame 450 (4.96 s) on were decided with their bound (6.97 to
7.91 s) before the pages of 8.0 s proved them, as ``analyze`` proves them: a DISTANCE 10 mm
high from 5 s PASSed live (``analyze``: FAIL by 9.996 mm). Now 7 rotations (420 frames), the
most a twist can wait and still find the steps of the page span before its frame kept for
``liveskip``'s allowance below (``liveskip.KEPT_FRAMES``, 8 rotations: older, unbounded there).
"""

from __future__ import annotations

import math

from odocan.host.judge.gapskips import took_none
from odocan.host.judge.livegapseen import LiveSeen
from odocan.host.judge.liveskip import KEPT_FRAMES, PAGE_FRAMES

UNIT_M = 2.0**-40  # a gap's bound rounded up to this (m): sums of them are exact floats
HOLD_FRAMES = KEPT_FRAMES - PAGE_FRAMES  # frames after a gap its proof is waited for (7 page
# rotations: module docstring)
KEPT_GAPS = 64  # gaps held at once


def exact_bound_m(extra_m: float) -> float:
    """A gap's bound above (m) rounded up to a whole ``UNIT_M``: the path's allowance above,
    their sum, is then exact (below 8 km), and a bound withdrawn leaves the twists after it at
    the very allowance of those before (the sum less it: a float's rounding left 3.6e-18 m, an
    empty interval, DISTANCE WRONG of a correct firmware). inf stays inf."""
    return extra_m if math.isinf(extra_m) else math.ceil(extra_m / UNIT_M) * UNIT_M


class HeldGaps:
    """The gaps of one life whose bound above the pages may yet withdraw (module docstring)."""

    gaps: list[tuple[int, float, float]]  # frame after it, its bound above (m), its bus time (s)
    upto: float  # the latest frame the twists waiting were asked judged up to
    dropped: int  # gaps decided with their bound because more than KEPT_GAPS waited

    def __init__(self) -> None:
        self.gaps = []
        self.upto = -1.0
        self.dropped = 0

    def add(self, seq: int, extra_m: float, t_s: float) -> None:
        """A gap into encoder frame ``seq`` (bus time ``t_s``) whose bound ``extra_m`` above was
        added to the path from there (none held when 0)."""
        if 0.0 < extra_m < math.inf:  # (inf less inf: no number; kept)
            self.gaps.append((seq, extra_m, t_s))
            if len(self.gaps) > KEPT_GAPS:
                del self.gaps[0]
                self.dropped += 1

    def first(self) -> int | None:
        """The frame after the oldest gap held (a twist naming it or later waits), None."""
        return self.gaps[0][0] if self.gaps else None

    def settle(self, seen: LiveSeen, reprimed: frozenset[int], seq: int, ends: bool
               ) -> list[tuple[int, float]]:
        """The gaps decided now, oldest first, each with the bound withdrawn (m; 0.0: kept):
        proven (``took_none`` of what the pages kept prove), told and not proven, waited for
        ``HOLD_FRAMES`` by encoder frame ``seq``, or ``ends`` (no page comes now)."""
        out: list[tuple[int, float]] = []
        while self.gaps:
            b, extra_m, b_s = self.gaps[0]
            if took_none(seen.proven(), reprimed)(b):
                out.append((b, extra_m))
            elif ends or seq - b >= HOLD_FRAMES or seen.told_after(b_s):
                out.append((b, 0.0))
            else:
                break
            del self.gaps[0]
        return out
