"""Whether the firmware's pages prove it took encoder frames inside a hole of the log's (issue #11,
rule 3: a FAIL must never blame a correct firmware), for the judges' ambiguity mirror
(``host.judge.ambiguity``).

A hole of the log's encoder frames as long as the firmware's ambiguous step (kobuki: 391
periods) is judged as a step the firmware could not read: it re-primes there (COUNTER_RESET)
and integrates nothing across. That holds for the sender's silence, when the firmware heard no
frame either. A recorder that lost the encoder frames alone is another thing: the firmware took
them one by one, in steps far shorter than that. Its ODOM_STATUS pages heard through the hole
tell which: ENC_E2E_OK (u16, exact along a chain of pages, ``host.judge.pagechain``) grew between
two pages p and q only if the firmware accepted a frame between the ticks that made them, so
such a frame came on the bus after p's tick less a period and at the latest when q was sent.

Each pair of consecutive pages of one chain inside the hole whose OK grew is such an interval;
with the frames before and after the hole (accepted: the reference steps from and to them) they
bound the firmware's longest step there: from the start of one interval to the end of the next.
While no frame was refused or dropped (REJECTED_FRAMES and OVERFLOWED_FRAMES the same from the
last FRAME_TOTALS page before the hole to the first after it: ``pagechain.chained_breaks``), every
frame accepted by E2E was integrated. If that longest step is below the ambiguous one the
firmware did not re-prime there: the judges take the hole as a gap (its ``gapbound``
allowance: the log does not hold the steps taken). Without such pages nothing changes: the hole
re-primes as before, and a firmware that integrated a guess across a silence still FAILs.

A pure function of the kept pages (``gapseen.Page``, ``gapseen.Totals`` rows), shared by the
whole-log and the streamed judge (``gapseen.PageEvidence.seen``) and the live one
(``livegapseen.LiveSeen.through``).
"""

from __future__ import annotations

import bisect
import math
from collections.abc import Sequence
from itertools import pairwise

SENT = 5  # gapseen.Page: its bus time (s)
OK_U = 6  # ENC_E2E_OK unwrapped along its chain
CHAIN = 7  # the chain's number
SLACK_PERIODS = 2  # the firmware counts periods on its clock, the judges on bus time
LONG_GAP_FRAMES = 16  # gaps missing fewer frames hold no two pages (one every ~50 periods)


def taken_through(pages: Sequence[tuple[float, ...]], totals: Sequence[tuple[float, ...]],
                  cycle_s: float, a_s: float, b_s: float, *, closed: bool = True) -> int | None:
    """The longest step (periods, ``SLACK_PERIODS`` included) the firmware can have taken
    between the encoder frames at bus times ``a_s`` and ``b_s`` (a hole of the log's encoder
    frames), when its pages (bus order) prove it took frames inside and refused none
    (``totals``; ``closed``: a FRAME_TOTALS page after the hole is required, the whole log's
    rule; the live judge steps at ``b_s`` before one came); None when they prove nothing."""
    return _taken(pages, [float(page[SENT]) for page in pages], totals,
                  [float(row[0]) for row in totals], (cycle_s, a_s, b_s), closed=closed)


def _taken(pages: Sequence[tuple[float, ...]], sent: list[float],
           totals: Sequence[tuple[float, ...]], totals_s: list[float],
           hole: tuple[float, float, float], *, closed: bool) -> int | None:
    """``taken_through`` with the pages' and the totals' bus times (``sent``, ``totals_s``)
    and ``hole``: the cycle, the frames' times before and after (s)."""
    cycle_s, a_s, b_s = hole
    if not _quiet(totals, totals_s, a_s, b_s, closed=closed):
        return None
    inside = pages[bisect.bisect_right(sent, a_s + cycle_s) : bisect.bisect_left(sent, b_s)]
    known = [(a_s, a_s)]  # bus-time intervals (s) each holding a frame the firmware took
    for p, q in pairwise(inside):
        if p[CHAIN] == q[CHAIN] and q[OK_U] > p[OK_U]:
            known.append((float(p[SENT]) - cycle_s, float(q[SENT])))
    if len(known) == 1:
        return None
    known.append((b_s, b_s))
    longest_s = max(later[1] - earlier[0] for earlier, later in pairwise(known))
    return math.ceil(longest_s / cycle_s) + SLACK_PERIODS


def _quiet(totals: Sequence[tuple[float, ...]], sent: list[float], a_s: float, b_s: float, *,
           closed: bool) -> bool:
    """The last FRAME_TOTALS page before ``a_s`` and every one after it (up to the first at or
    after ``b_s``, which ``closed`` requires) count the same refused and dropped frames
    (``sent``: their bus times)."""
    first = bisect.bisect_left(sent, a_s) - 1
    last = bisect.bisect_left(sent, b_s)
    if first < 0 or (closed and last >= len(totals)):
        return False
    breaks = {int(row[3]) for row in totals[first : last + 1]}
    return len(breaks) == 1


def through_gaps(pages: Sequence[tuple[float, ...]], totals: Sequence[tuple[float, ...]],
                 cycle_s: float, gaps: dict[int, tuple[float, float, int]]) -> dict[int, int]:
    """``taken_through`` of each gap (its frame after: the bus times of the frames around it)
    whose pages prove frames taken."""
    out = {}
    sent, totals_s = [float(page[SENT]) for page in pages], [float(row[0]) for row in totals]
    for frame, (a_s, b_s, _) in gaps.items():
        periods = _taken(pages, sent, totals, totals_s, (cycle_s, a_s, b_s), closed=True)
        if periods is not None:
            out[frame] = periods
    return out
