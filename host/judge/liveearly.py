"""A live hold ended as soon as the firmware's evidence settles the frame that opened it (issue
#11: one judge; rule 5: a FAIL never blames a correct firmware, an OK never hides a wrong pose;
``host.judge.livesettle``).

A hold opens at an encoder frame the stamps cannot decide: read strictly, or as a recorder that
stamped the frame before it late (wide), or the frame itself (narrow), its verdict differs
(``e2e_held.readings_differ``). A bus that delays a frame (``delay=0.1:20``: 20 ms late) makes
two encoder frames come one period apart or less, which is just what a starved recorder's burst
makes of them: the stamps alone cannot tell the two. The firmware's evidence can, and most of it
comes soon: the poses' ENC_COUNTER names the frame it integrated last, 20 ms apart, and proves
the frame taken or skipped within a lock-out's 16 periods (``e2e_evidence.pose_evidence``).
Only the ENC_E2E pages, one in a 0.6 s rotation, come late, and they change a verdict only
where the poses and the stamps disagree (``e2e_pages.by_pages``: the frames of a recorder's
release; ``e2e_skipveto``: spans where the poses' verdicts are off the firmware's count and the
stamps' are not) or at a frame a COUNTER cycle on (``e2e_repeats``, never ended early).

So from ``EARLY_S`` after its first frame, every ``RETRY_S`` of bus time, the frames judged
before the hold and those held are judged whole (``check_frames``): the hold ends when the poses
prove that first frame taken or skipped, no verdict of the stamps was changed by the evidence
(``touched``: the stamps read as the bus's, the firmware agrees with them) and no two frames are
stamped closer than a bus delivers them (``BURST_S``: a recorder's bunching, which the pages
may yet re-read). Its verdict is then the one the whole log gives it (``verdict``).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from odocan.host.protocol import busfacts
from odocan.host.protocol.e2e import check_frames
from odocan.host.protocol.e2e_evidence import ALIKE_S, BURST_S

if TYPE_CHECKING:
    import numpy.typing as npt

    from odocan.host.io.logs import FrameArrays
    from odocan.host.protocol.dbcplan import DatabaseSpec

# bus time from a hold's first frame before the evidence is read (s): a lock-out's 16 periods,
# over which the poses may hold one name, then two pose sends naming past it
EARLY_S = (busfacts.ENC_COUNTER_LAP * busfacts.ENC_CYCLE_S + 2 * busfacts.POSE_PERIOD_S)
RETRY_S = 2 * busfacts.POSE_PERIOD_S  # the evidence read again this often while none settles
Frames = tuple["FrameArrays", int, "DatabaseSpec"]  # judged before and held, the first held's place


class EarlyEnd:
    """When a hold's evidence is read, and the verdict it gave its first frame (docstring)."""

    __slots__ = ("_at_s", "reads", "verdict")

    def __init__(self) -> None:
        self._at_s = math.inf  # bus time of the next read (s); inf: none
        self.verdict: bool | None = None  # the first held frame's, once settled early
        self.reads = 0  # evidence reads made (each a ``check_frames`` of a hold's frames)

    def open(self, at_s: float) -> None:
        """A hold opened (or went on): its evidence read from bus time ``at_s`` (inf: never)."""
        self._at_s, self.verdict = at_s, None

    def pending(self) -> bool:
        """Whether the hold may still end early (its evidence read, or to be)."""
        return self._at_s < math.inf

    def tried(self, t_s: float) -> bool:
        """Whether the evidence is read at a frame of bus time ``t_s`` (then next ``RETRY_S``
        on)."""
        if t_s < self._at_s:
            return False
        self._at_s = t_s + RETRY_S
        return True

    def settled(self, frames: Frames) -> bool:
        """Whether the evidence settles the first held frame (``frames``: ``SettleHold``'s);
        its verdict then kept in ``verdict``."""
        arrays, first, db = frames
        self.reads += 1
        gaps_s = np.diff(arrays.timestamp_s)
        if bool(((gaps_s > ALIKE_S) & (gaps_s < BURST_S)).any()):
            return False  # a recorder bunched them: its release the pages may re-read
        touched: list[npt.NDArray[np.intp]] = []
        decided = {first: False}
        _, accepted = check_frames(arrays, db, touched, decided, settle_all=True,
                                   only=busfacts.ENC_MESSAGE)  # its encoder frames' verdicts
        if any(len(at) for at in touched) or not decided[first]:
            return False
        self.verdict, self._at_s = bool(accepted[first]), math.inf
        return True
