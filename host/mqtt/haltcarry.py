"""The offsets a halt's surviving paths allow, carried into the stretch after it
(``host.mqtt.haltstretch``, ``host.mqtt.haltcross``).

A stretch re-started at the firmware's own pose knows its offset only to the base's rounding
(+-half an LSB, ``haltpath.interval``), so a firmware that shifted its pose by less than one LSB
at every halt drifted unseen, halt after halt. But the crossing's paths were stepped from the
stretch before the halt up to the new base's frame, and their offsets (firmware - their
reference) still hold there: the firmware's offset from the new base's reference is a path's
offset plus how far that path's reference is from the base (its X, Y, HEADING), whichever path
the firmware took. Each path's offsets move by what can move between two references that
started apart: the turn of the path's displacement by its heading offset (``haltpath.turned_m``)
and the fixed point against float64 (``haltpath.ARITH_*``, the bounds ``narrow_offsets`` uses).
The firmware took one of the paths, so its offsets lie in one path's triple (x, y, heading),
not merely in their hull: the new stretch keeps the triples its own samples still meet, one a
path (``keep_offsets``, at its base and at every sample after), its intervals their hull; it is
wrong once none is left. The paths of one halt start up to 0.8 LSB of X apart (merged, primed,
the FIFO's frames), so their hull alone widened the carried interval by more than a 0.1 LSB
drift a halt, and that firmware PASSed (seeds 1, 5, 6 of ``test_fleet_halt_carry``). The
offsets carry from stretch to stretch while every halt's crossing is judged; a drift the halts
add up shows once it leaves them. A crossing lost, or a re-start not judged, carries nothing:
the next base starts afresh.
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
_NAMES = ("x", "y", "heading")
_LSBS = (POSITION_LSB_M, POSITION_LSB_M, HEADING_LSB_RAD)


Offsets = tuple[Interval, Interval, Interval]  # x, y (m), heading (rad)


def carry_offsets(paths: Sequence[Stretch], base: Stretch) -> list[Offsets] | None:
    """The offsets each surviving path (stepped to the base's frame) allows the new stretch
    ``base``, from the base's reference, one triple a path: the firmware took one of the paths,
    so its offsets lie in one of them (not only in their hull; None: no path to carry from)."""
    if not paths or any(path.seq != base.seq for path in paths):
        return None
    ref, carried = base.ref, []
    for p in paths:
        turn_x, turn_y = turned_m(p)
        heading_rad = math.remainder(p.ref.heading_rad - ref.heading_rad, _TURN)
        carried.append((_moved(p.x, p.ref.x_m - ref.x_m, _arith_m(p), turn_x),
                        _moved(p.y, p.ref.y_m - ref.y_m, _arith_m(p), turn_y),
                        _moved(p.heading, heading_rad, ARITH_RAD_PER_STEP * p.steps)))
    return carried


def keep_offsets(stretch: Stretch, carried: Sequence[Offsets]
                 ) -> tuple[list[Offsets], tuple[str, float] | None]:
    """The ``carried`` offsets the stretch's own (its samples') still meet, the stretch's
    narrowed to their hull; with none left, the field that emptied the nearest and by how many
    LSB (the stretch is wrong: no path the firmware could have taken explains its samples)."""
    own = (stretch.x, stretch.y, stretch.heading)
    x, y, heading = own
    kept = [c for c in carried if c[0].lo <= x.hi and x.lo <= c[0].hi and c[1].lo <= y.hi
            and y.lo <= c[1].hi and c[2].lo <= heading.hi and heading.lo <= c[2].hi]
    if not kept:
        return [], min((_gap(own, c) for c in carried), key=lambda gap: gap[1])
    for axis, allowed in enumerate(own):  # each kept triple meets it: never empty
        allowed.lo = max(allowed.lo, min(c[axis].lo for c in kept))
        allowed.hi = min(allowed.hi, max(c[axis].hi for c in kept))
    return kept, None


def _gap(own: Offsets, carried: Offsets) -> tuple[str, float]:
    """The field of ``carried`` the farthest from ``own`` and by how many LSB."""
    return max(((name, (max(a.lo, b.lo) - min(a.hi, b.hi)) / lsb)
                for name, a, b, lsb in zip(_NAMES, own, carried, _LSBS, strict=True)),
               key=lambda gap: gap[1])


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
