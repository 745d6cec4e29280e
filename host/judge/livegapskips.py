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

A gap inside a run the pages prove the firmware received exactly the log's frames over
(``Seen.received``, ``MARGIN_FRAMES`` inside, no re-prime in it) is lowered likewise to
``gapreceived``'s allowance, the merge error over the refused frames heard in it
(``LiveFill.known``): kobuki random 448, ``delay=0.3:55,busoff=5:0.2``, kept the bus-off's
15 periods at ``gapbound``'s 15.98 mm live where ``analyze`` proves them 0, and a pose raised
10 mm from the first pose after the bus-off PASSed live (0.057 mm beyond) where ``analyze``
FAILs it (6.12 mm).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from odocan.host.judge.gapreceived import MARGIN_FRAMES, received_allowance_m
from odocan.host.judge.gapseen import Seen
from odocan.host.judge.gapskips import frames_around, rows_allowance_m
from odocan.host.judge.reference import PROFILE_SPEED, Geometry, SpeedBound

if TYPE_CHECKING:
    from odocan.host.judge.livefill import LiveFill

KEPT_FRAMES = 512  # the latest accepted encoder frames kept (5 s at 100 Hz: pages come in 1.2)
LivePart = tuple[bool, int, int, float, int]  # ``liveplace.Part``: gap?, first, last, m, frame


class LiveGapSkips:
    """The latest accepted encoder frames' sender numbers and counts, and the reference's
    geometry, counter width and integrator the gaps are bounded with."""

    ring: list[tuple[int, int, int, int]]  # per frame (seq mod KEPT_FRAMES): seq, sender, l, r
    reference: tuple[Geometry, int, str] | None  # the latest placement's (``StallPlacer.shift``)
    fill: LiveFill | None  # the refused frames heard (``gapreceived``'s known frames)
    speed: SpeedBound  # the plausibility bound of a step (``StallPlacer.max_wheel_speed_mm_s``)

    def __init__(self) -> None:
        self.ring = [(-1, 0, 0, 0)] * KEPT_FRAMES
        self.reference = None
        self.fill = None
        self.speed = PROFILE_SPEED

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
            allowance = min(math.inf if m is None else self.allowance_m(part[1], m),
                            self.received_m(part[1], seen, reprimed))
            if allowance < part[3]:
                out.append((part, allowance))
        return out

    def received_m(self, b: int, seen: Seen, reprimed: frozenset[int]) -> float:
        """``gapreceived``'s allowance of the gap into frame ``b`` (module docstring); inf where
        no received run holds it, its frames or the refused ones heard in it are no longer
        kept, or no reference is known."""
        inside = any(lo + MARGIN_FRAMES <= b - 1 and b + MARGIN_FRAMES <= hi
                     and not any(lo < r <= hi for r in reprimed) for lo, hi in seen.received)
        before, after = self.ring[(b - 1) % KEPT_FRAMES], self.ring[b % KEPT_FRAMES]
        if (not inside or self.reference is None or self.fill is None or b < 1
                or before[0] != b - 1 or after[0] != b):
            return math.inf
        periods = after[1] - before[1]
        known = self.fill.known(before[1], periods)
        return received_allowance_m(known, (before[2], before[3]), (after[2], after[3]), periods,
                                    *self.reference,
                                    self.speed)
