"""The log's lone pose halves against the replayed firmware (issue #11, rule 5;
``host.judge.replay_compare.versus_log``).

An ODOM_POSE_X (X, HEADING) or ODOM_POSE_Y (Y, TURNS) whose partner naming the same encoder
frame the bus lost is compared on what it carries with the replayed firmware's pose at that
frame, as a pair is: its position axis as it is up to the log's first gap, after it by the drift
of that axis's offset from the offset of the first pose both name after the gap (the pairs'
``drift_between_gaps_m``, its rounding, the replay turned by the heading offset of its anchor);
its heading read nearest the replayed heading plus that offset (``posehalves``, the judges'
rule: an X half's whole turns, a Y half's binary angle) less its anchor's LSB. Only where the
pairs are compared: a half in a stretch of the log (from its start or a hole) without a pose
both name has no anchor, and is counted as not compared. Before, only frames both halves
named were compared: a lone X raised 10 m PASSed the replay (kobuki random seed 5, drop=0.1:
35 X frames "not compared")."""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from odocan.host.judge.posehalves import x_half_heading_bam, y_half_heading_bam
from odocan.host.judge.samples import HEADING_LSB_RAD, POSITION_LSB_M

IntArray = npt.NDArray[np.int64]
FloatArray = npt.NDArray[np.float64]
BoolArray = npt.NDArray[np.bool_]
Halves = dict[int, list[tuple[int, int]]]


def turned(xy: npt.ArrayLike, turn_bam: npt.ArrayLike) -> FloatArray:
    """Positions ``xy`` (n x 2) turned by ``turn_bam`` (BAM16 units, one per row)."""
    points = np.asarray(xy, dtype=np.float64).reshape(-1, 2)
    angle = np.asarray(turn_bam, dtype=np.float64) * HEADING_LSB_RAD
    cos, sin = np.cos(angle), np.sin(angle)
    out: FloatArray = np.c_[cos * points[:, 0] - sin * points[:, 1],
                            sin * points[:, 0] + cos * points[:, 1]]
    return out


@dataclass(frozen=True)
class LoneHalves:
    """Every half of a log naming a tick its partner names not: one row per frame sent (a
    resend too), in tick order."""

    tick: IntArray
    axis: IntArray  # 0: an ODOM_POSE_X (X, HEADING); 1: an ODOM_POSE_Y (Y, TURNS)
    value: IntArray  # X or Y raw (0.1 mm)
    part: IntArray  # HEADING (BAM16) or TURNS raw
    resent_lsb: float  # the largest position difference of a resend from the first at a tick

    @classmethod
    def of(cls, px: Halves, py: Halves) -> LoneHalves:
        """The lone halves of ``replay_compare.halves_by_tick``'s ``px`` and ``py``."""
        rows = sorted((t, axis, v, e) for axis, (mine, other) in enumerate(((px, py), (py, px)))
                      for t in mine.keys() - other.keys() for v, e in mine[t])
        resent = [abs(v - mine[t][0][0]) for mine, other in ((px, py), (py, px))
                  for t in mine.keys() - other.keys() for v, _ in mine[t][1:]]
        table = np.array(rows, dtype=np.int64).reshape(-1, 4)
        return cls(table[:, 0], table[:, 1], table[:, 2], table[:, 3],
                   float(max(resent, default=0)))

    def select(self, keep: BoolArray) -> LoneHalves:
        """The rows ``keep``."""
        return LoneHalves(self.tick[keep], self.axis[keep], self.value[keep], self.part[keep],
                          self.resent_lsb)

    def x_ticks(self) -> set[int]:
        """The ticks the lone ODOM_POSE_X halves name."""
        return set(self.tick[self.axis == 0].tolist())


@dataclass(frozen=True)
class Anchoring:
    """How ``versus_log`` compares the pairs, at their ``common`` ticks: the heading offset
    (``turn``, BAM16) and whether it is an anchor's (``anchored``), segments opened by the
    log's holes (``hole_ends``: the first tick after each); the position drift's segments
    (``gap_ends``), the pairs' offsets (``offset``: log - turned replay, raw, n x 2; None: the
    positions after the first gap are not compared) and the replay's positions
    (``replay_xy``); ``first_gap``: the last tick before the log's first gap, None for a log
    cut mid-drive (no position compared as it is)."""

    common: IntArray
    hole_ends: IntArray
    turn: IntArray
    anchored: BoolArray
    gap_ends: IntArray
    offset: FloatArray | None
    replay_xy: IntArray
    first_gap: int | None


@dataclass(frozen=True)
class LoneFigures:
    """The lone halves compared (``x``, ``y``: how many frames of each kind), those not (no
    replayed pose at their tick, or no anchor), and the largest differences (None: none)."""

    x: int = 0
    y: int = 0
    not_compared: int = 0
    x_ticks: frozenset[int] = frozenset()
    before_gap_m: float | None = None  # positions as they are, up to the first gap
    raw_m: float | None = None  # positions as they are, everywhere (None mid-drive)
    drift_m: float | None = None  # position drift between gaps, after the first
    heading_rad: float | None = None


def _same_segment(ends: IntArray, common: IntArray, ticks: IntArray) -> tuple[IntArray,
                                                                               BoolArray]:
    """Per tick of ``ticks``: the row of the first ``common`` tick of its segment (opened by
    ``ends``), and whether its segment holds one."""
    if len(common) == 0:
        return np.zeros(len(ticks), dtype=np.int64), np.zeros(len(ticks), dtype=np.bool_)
    seg_common = np.searchsorted(ends, common, side="right")
    seg = np.searchsorted(ends, ticks, side="right")
    row = np.minimum(np.searchsorted(seg_common, seg), len(common) - 1).astype(np.int64)
    return row, np.asarray(seg_common[row] == seg, dtype=np.bool_)


def versus_replay(lone: LoneHalves, new: dict[int, list[tuple[int, int, int]]],
                  at: Anchoring) -> LoneFigures:
    """``lone`` against the replayed poses ``new`` (module docstring)."""
    row, anchor = _same_segment(at.hole_ends, at.common, lone.tick)
    ok = np.isin(lone.tick, np.fromiter(new, dtype=np.int64, count=len(new))) & anchor
    half, row = lone.select(ok), row[ok]
    figures = LoneFigures(not_compared=int(np.count_nonzero(~ok)))
    if len(half.tick) == 0:
        return figures
    rep = np.array([new[t][0] for t in half.tick.tolist()], dtype=np.int64)
    turn, loose = at.turn[row], at.anchored[row].astype(np.int64)
    near = rep[:, 2] + turn
    read = np.where(half.axis == 0, x_half_heading_bam(half.part, near),
                    y_half_heading_bam(half.part, near))
    heading = np.maximum(np.abs(read - near) - loose, 0) * HEADING_LSB_RAD
    mine = np.arange(len(half.tick))
    as_is = np.abs(half.value - rep[mine, half.axis]) * POSITION_LSB_M
    before = as_is[half.tick <= at.first_gap] if at.first_gap is not None else as_is[:0]
    return LoneFigures(
        x=int(np.count_nonzero(half.axis == 0)), y=int(np.count_nonzero(half.axis == 1)),
        not_compared=figures.not_compared, x_ticks=frozenset(half.x_ticks()),
        before_gap_m=float(before.max()) if len(before) else None,
        raw_m=None if at.first_gap is None else float(as_is.max()),
        drift_m=_drift_m(half, rep, (turn, loose), at), heading_rad=float(heading.max()))


def _drift_m(half: LoneHalves, rep: IntArray, anchor: tuple[IntArray, IntArray],
             at: Anchoring) -> float | None:
    """The largest drift of a lone half's offset (its axis) from the offset of the first pair
    of its segment between gaps, after the first gap, less the pairs' rounding
    (``replay_compare.drift_between_gaps_m``; ``anchor``: the heading offset the replay is
    turned by, and 1 where it is an anchor's); None when positions are not compared there."""
    turn, loose = anchor
    if at.offset is None:
        return None
    row, has = _same_segment(at.gap_ends, at.common, half.tick)
    keep = has & (np.searchsorted(at.gap_ends, half.tick, side="right") > 0)
    if not keep.any():
        return 0.0
    axis, start = half.axis[keep], row[keep]
    mine = turned(rep[keep, :2], turn[keep])[np.arange(len(axis)), axis]
    offset = half.value[keep] - mine
    travel = np.hypot(*(rep[keep, :2] - at.replay_xy[start]).T.astype(np.float64))
    rounding = np.where(loose[keep] > 0, 2.5 + HEADING_LSB_RAD * travel, 1.0)
    moved = np.maximum(np.abs(offset - at.offset[start, axis]) - rounding, 0)
    return float(moved.max()) * POSITION_LSB_M


def unpaired(named: IntArray, common: Collection[int], lone: LoneFigures) -> int:
    """The log's ODOM_POSE_X frames (the ticks they name, ``named``) compared neither in a pair
    nor alone."""
    compared = np.fromiter({*common, *lone.x_ticks}, dtype=np.int64)
    return int(np.count_nonzero((named >= 0) & ~np.isin(named, compared)))
