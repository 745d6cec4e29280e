"""The live judge's gaps inside runs the firmware's pages prove it received exactly the log's
frames and refused ``m`` of them (``host.judge.gapskips``: issue #11, rule 5: a PASS must never
hide a wrong pose; one judge).

The monitor and the bridge place their reference after a gap at the next sample, with
``gapbound``'s allowance (``liveplace.StallPlacer``): the pages that prove what the firmware took
there come a page rotation later. When they prove such a run around a gap placed (``Seen.skipped``,
the pages kept by ``livegapseen.LiveSeen``), the gap's part of the placement is lowered to
``gapskips``' allowance, the merge error of the frames from ``m`` before the gap to ``m`` after
it, as ``analyze`` gives it (``gapskips.rows_allowance_m``, the same numbers), and the placement
made again within it (``StallPlacer.withdraw``): a pose 10 mm off from a bus-off's end, which
``gapbound``'s 121.9 mm absorbed live (kobuki seed 24, ``busoff=4:0.3``), FAILs the live judges
too. The frames are kept as they are accepted, the latest ``KEPT_FRAMES`` (a fixed ring: no
growth), each with its sender number (``livefill.LiveFill.sender``) and counts.
"""

from __future__ import annotations

import math

from odocan.host.judge.gapseen import Seen
from odocan.host.judge.gapskips import frames_around, rows_allowance_m
from odocan.host.judge.reference import Geometry

KEPT_FRAMES = 512  # the latest accepted encoder frames kept (5 s at 100 Hz: pages come in 1.2)
LivePart = tuple[bool, int, int, float, int]  # ``liveplace.Part``: gap?, first, last, m, frame


class LiveGapSkips:
    """The latest accepted encoder frames' sender numbers and counts, and the reference's
    geometry, counter width and integrator the gaps are bounded with."""

    ring: list[tuple[int, int, int, int]]  # per frame (seq mod KEPT_FRAMES): seq, sender, l, r
    reference: tuple[Geometry, int, str] | None  # the latest placement's (``StallPlacer.shift``)

    def __init__(self) -> None:
        self.ring = [(-1, 0, 0, 0)] * KEPT_FRAMES
        self.reference = None

    def heard(self, seq: int, sender: int, left: int, right: int) -> None:
        """Accepted encoder frame ``seq``: its sender number and wire counts."""
        self.ring[seq % KEPT_FRAMES] = (seq, sender, left, right)

    def allowance_m(self, b: int, m: int) -> float:
        """``gapskips``' allowance of the gap into frame ``b`` with ``m`` frames refused around
        it; inf where a frame is no longer kept or no reference is known."""
        first, end = frames_around(b, m)
        if self.reference is None or first < 0:
            return math.inf
        rows: list[tuple[int, int, int] | None] = []
        for at in range(first, end):
            seq, sender, left, right = self.ring[at % KEPT_FRAMES]
            rows.append((sender, left, right) if seq == at else None)
        return rows_allowance_m(rows, *self.reference)

    def lowered(self, parts: list[LivePart], seen: Seen, reprimed: frozenset[int]
                ) -> list[tuple[LivePart, float]]:
        """The gap parts (of finite allowance) whose gap ``seen`` proves inside such a run,
        each with its lower allowance (m) where ``gapskips``' is below the part's."""
        out = []
        for part in parts:
            if not part[0] or math.isinf(part[3]):
                continue
            m = seen.skipped(part[1], reprimed)
            allowance = math.inf if m is None else self.allowance_m(part[1], m)
            if allowance < part[3]:
                out.append((part, allowance))
        return out
