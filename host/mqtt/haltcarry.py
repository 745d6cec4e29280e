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

The triples a stretch still keeps at the next halt go on as its ``boxes`` (``haltpath.Stretch``):
the crossing's paths fork them, each sample narrows each box (a path dies when none is left),
and each surviving path carries each of its boxes into the next stretch. Before, the next halt
forked the stretch's hull of them, and the ways' spread came back at every halt: X 0.03 LSB a
halt over 60 s (2 LSB off by the end) PASSed at seed 1. A halt's ways times the boxes before can
be some 200: more than ``MOST_BOXES`` are merged into hulls of neighbours (``_merged``: sound,
coarser).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M
from odocan.host.mqtt.haltpath import (
    ARITH_M_PER_M,
    ARITH_RAD_PER_STEP,
    Interval,
    Offsets,
    Stretch,
    hull_into,
    turned_m,
)

_TURN = 2.0 * math.pi
_NAMES = ("x", "y", "heading")
_LSBS = (POSITION_LSB_M, POSITION_LSB_M, HEADING_LSB_RAD)
MOST_BOXES = 8  # a stretch's boxes beyond it merged with neighbours (sound: their hull; 24 cost
# the halt judges 1.5 times their instructions more than 8 and changed no verdict measured)
MERGE_GRID_LSB = 0.02  # the finest grid boxes are merged on (``_merged``)


def carry_offsets(paths: Sequence[Stretch], base: Stretch) -> list[Offsets] | None:
    """The offsets each surviving path (stepped to the base's frame) allows the new stretch
    ``base``, from the base's reference, one triple a path and box the path still kept (the
    ways of the halts before: ``Stretch.boxes``): the firmware took one way at every halt, so
    its offsets lie in one of them (not only in their hull; None: no path to carry from)."""
    if not paths or any(path.seq != base.seq for path in paths):
        return None
    ref, carried = base.ref, []
    for p in paths:
        heading_rad = math.remainder(p.ref.heading_rad - ref.heading_rad, _TURN)
        shift = (p.ref.x_m - ref.x_m, p.ref.y_m - ref.y_m, heading_rad)
        widen = (_arith_m(p), ARITH_RAD_PER_STEP * p.steps)
        for box in p.boxes or [(p.x, p.y, p.heading)]:
            carried.append(_carried_box(p, box, shift, widen))
    return carried


def _carried_box(path: Stretch, box: Offsets, shift: tuple[float, float, float],
                 widen: tuple[float, float]) -> Offsets:
    """``box`` of ``path`` (offsets at its base) as offsets from another reference ``shift``
    (x, y m; heading rad) away at the path's last frame, its heading's turn added, widened by
    the arithmetic ``widen`` (m, rad) each side."""
    x, y, heading = box
    turn_x, turn_y = turned_m(path, heading)
    return (_moved(x, shift[0], widen[0], turn_x), _moved(y, shift[1], widen[0], turn_y),
            _moved(heading, shift[2], widen[1]))


def keep_offsets(stretch: Stretch, carried: Sequence[Offsets]
                 ) -> tuple[list[Offsets], tuple[str, float] | None]:
    """The ``carried`` offsets the stretch's own (its samples') still meet, each cut to the
    stretch's own and kept as its ``boxes`` (merged down to ``MOST_BOXES``), the stretch's own
    narrowed to their hull; with none left, the field that emptied the nearest and by how many
    LSB (the stretch is wrong: no path the firmware could have taken explains its samples)."""
    own = (stretch.x, stretch.y, stretch.heading)
    x, y, heading = own
    kept = [(Interval(max(c[0].lo, x.lo), min(c[0].hi, x.hi)),
             Interval(max(c[1].lo, y.lo), min(c[1].hi, y.hi)),
             Interval(max(c[2].lo, heading.lo), min(c[2].hi, heading.hi)))
            for c in carried if c[0].lo <= x.hi and x.lo <= c[0].hi and c[1].lo <= y.hi
            and y.lo <= c[1].hi and c[2].lo <= heading.hi and heading.lo <= c[2].hi]
    if not kept:
        return [], min((_gap(own, c) for c in carried), key=lambda gap: gap[1])
    kept = _merged(kept, MOST_BOXES)
    hull_into(own, kept)
    stretch.boxes = kept
    return kept, None


def _merged(boxes: list[Offsets], most: int) -> list[Offsets]:
    """``boxes`` merged (their hull: sound) while more than ``most``: those whose centres fall
    in one cell of a grid ``MERGE_GRID_LSB`` LSB wide on every field, the grid twice as wide
    at every pass (linear in the boxes: a halt's ways times the boxes before can be 200)."""
    grid = MERGE_GRID_LSB
    while len(boxes) > most:
        cells: dict[tuple[int, ...], Offsets] = {}
        for box in boxes:
            key = tuple(round((i.lo + i.hi) / (2.0 * grid * lsb))
                        for i, lsb in zip(box, _LSBS, strict=True))
            held = cells.get(key)
            cells[key] = box if held is None else _hull(held, box)
        boxes, grid = list(cells.values()), 2.0 * grid
    return boxes


def _hull(a: Offsets, b: Offsets) -> Offsets:
    """The smallest box holding ``a`` and ``b``."""
    (ax, ay, ah), (bx, by, bh) = a, b
    return (Interval(min(ax.lo, bx.lo), max(ax.hi, bx.hi)),
            Interval(min(ay.lo, by.lo), max(ay.hi, by.hi)),
            Interval(min(ah.lo, bh.lo), max(ah.hi, bh.hi)))


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
