"""The offsets a halt's surviving paths allow, carried into the stretch after it
(``host.mqtt.haltstretch``, ``host.mqtt.haltcross``).

A stretch re-started at the firmware's own pose knows its offset only to the base's rounding
(+-half an LSB, ``haltpath.interval``), so a firmware that shifted its pose by less than one LSB
at every halt drifted unseen, halt after halt. But the crossing's paths were stepped from the
stretch before the halt up to the new base's frame, and their offsets (firmware - their
reference) still hold there: the firmware's offset from the new base's reference is a path's
offset plus how far that path's reference is from the base (its X, Y, HEADING), whichever path
the firmware took. So the new stretch keeps only the offsets the hull over the surviving paths
allows, each widened by what can move between two references that started apart: the turn
of the path's displacement by its heading offset and the fixed point against float64
(``haltpath.ARITH_*``, the bounds ``narrow_offsets`` uses). The offsets carry from stretch to
stretch while every halt's crossing is judged; a drift the halts add up shows once it leaves
them. A crossing lost, or a re-start not judged, carries nothing: the next base starts afresh.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.mqtt.haltpath import (
    ARITH_M_PER_M,
    ARITH_RAD_PER_STEP,
    Interval,
    Stretch,
    turned_m,
)

_TURN = 2.0 * math.pi


def carry_offsets(paths: Sequence[Stretch], base: Stretch) -> tuple[str, float] | None:
    """Narrow the new stretch ``base``'s offsets (its base's rounding) to the hull the surviving
    ``paths`` (stepped to the base's frame) allow, per axis; the first field whose interval
    emptied and by how many LSB (None: every one still holds, or no path to carry from)."""
    if not paths or any(path.seq != base.seq for path in paths):
        return None
    ref = base.ref
    heading = _hull([_moved(p.heading, math.remainder(p.ref.heading_rad - ref.heading_rad, _TURN),
                            ARITH_RAD_PER_STEP * p.steps) for p in paths])
    turns = [turned_m(p) for p in paths]
    x = _hull([_moved(p.x, p.ref.x_m - ref.x_m, _arith_m(p), turn)
               for p, (turn, _) in zip(paths, turns, strict=True)])
    y = _hull([_moved(p.y, p.ref.y_m - ref.y_m, _arith_m(p), turn)
               for p, (_, turn) in zip(paths, turns, strict=True)])
    for name, allowed, carried, lsb in (("x", base.x, x, POSITION_LSB_M),
                                        ("y", base.y, y, POSITION_LSB_M),
                                        ("heading", base.heading, heading, HEADING_LSB_RAD)):
        allowed.lo, allowed.hi = max(allowed.lo, carried.lo), min(allowed.hi, carried.hi)
        if allowed.lo > allowed.hi:
            return name, (allowed.lo - allowed.hi) / lsb
    return None


def _arith_m(path: Stretch) -> float:
    """The fixed point against float64 over the path's displacement (``haltpath.ARITH_M_PER_M``,
    the bound ``narrow_offsets`` uses besides the rounding)."""
    return ARITH_M_PER_M * math.hypot(path.ref.x_m - path.x0_m, path.ref.y_m - path.y0_m)


def _moved(offsets: Interval, shift: float, widen: float, turn: Interval | None = None
           ) -> Interval:
    """``offsets`` from another reference ``shift`` away, plus what the heading offset turned
    (``turn``: ``haltpath.turned_m``), widened by ``widen`` each side."""
    turn = Interval(0.0, 0.0) if turn is None else turn
    return Interval(offsets.lo + shift + turn.lo - widen, offsets.hi + shift + turn.hi + widen)


def _hull(intervals: list[Interval]) -> Interval:
    """The smallest interval holding every one of ``intervals``."""
    return Interval(min(i.lo for i in intervals), max(i.hi for i in intervals))
