"""A gap inside a run of the log's encoder frames over which the firmware received exactly the
log's frames and refused ``m`` of them (issue #11, rule 5: a PASS must never hide a wrong pose;
``gapchecked.skipped_frames``, ``gapseen.Seen.skips``).

``gapbound`` allows a gap the worst split of its travel into its periods: the firmware may have
taken frames the log lacks (metres on pmir's 4 m/s bound over a 0.3 s bus-off). Where its E2E
counts prove it received no frame the log lacks, it took none of the gap's: across the gap its
step runs from the last frame it took before to the first it took after, both the log's. It
refused ``m`` of the log's frames there (REPEATED after a bus-off's held frames, kobuki seed
24: the host took it), so that step starts at most ``m`` frames before the gap and ends at most
``m`` after it; the reference takes every one of them, the gap as one step (the firmware's
too). Its position then differs from the reference's by that run's merge error, at most
``breaks.merge_allowance_m`` over the frames from ``m`` before the gap to ``m`` after it (their
counts the log's, gated as the firmware's). That bound, not gapbound's, is the gap's allowance
(the smaller of the two, both true bounds). The whole-log judge reads those frames from the
log's encoder frames; the streamed one keeps them as they go by (``SkipCounts``), the same
numbers, bit for bit; the live one (``livegapskips``: the monitor, the bridge) keeps the latest
frames and lowers a gap's placement to it when the pages prove the run (``rows_allowance_m``).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from odocan.host.judge.breaks import merge_allowance_m
from odocan.host.judge.gapseen import Seen
from odocan.host.judge.reference import Geometry
from odocan.host.judge.samples import Encoders, IntArray


def skip_allowance_m(left: IntArray, right: IntArray, seq: IntArray, geometry: Geometry,
                     bits: int, integrator: str) -> float:
    """The allowance (m) of a gap whose frames from ``m`` before it to ``m`` after it have
    wire counts ``left``, ``right`` and sender numbers ``seq`` (module docstring)."""
    return merge_allowance_m(np.asarray(left, dtype=np.int64), np.asarray(right, dtype=np.int64),
                             geometry, bits, integrator, np.asarray(seq, dtype=np.int64))


def frames_around(b: int, m: int) -> tuple[int, int]:
    """The encoder frames (first, end excluded) whose counts bound the gap into ``b``."""
    return b - 1 - m, b + m + 1


@dataclass
class SkipCounts:
    """The streamed judge's encoder frames inside ``spans`` (``Seen.skips``: first, last, m),
    kept as the life's accepted frames go by (``feed``, from its first frame)."""

    spans: list[tuple[int, int, int]]
    _count: int = 0
    _kept: dict[int, tuple[int, int, int]] = field(default_factory=dict)  # frame: seq, l, r

    def feed(self, enc: Encoders) -> None:
        lo, hi = self._count, self._count + len(enc.index)
        self._count = hi
        for first, last, _ in self.spans:
            for at in range(max(first, lo), min(last + 1, hi)):
                self._kept[at] = (int(enc.seq[at - lo]), int(enc.left[at - lo]),
                                  int(enc.right[at - lo]))

    def allowance_m(self, b: int, m: int | None, geometry: Geometry, bits: int,
                    integrator: str) -> float:
        """``skip_allowance_m`` of the gap into ``b`` (``m``: ``Seen.skipped``; inf where it
        is None or a frame was not kept), as ``skipped_at``."""
        if m is None:
            return math.inf
        first, end = frames_around(b, m)
        if first < 0:
            return math.inf
        return rows_allowance_m([self._kept.get(at) for at in range(first, end)], geometry,
                                bits, integrator)


def rows_allowance_m(rows: list[tuple[int, int, int] | None], geometry: Geometry, bits: int,
                     integrator: str) -> float:
    """``skip_allowance_m`` of the frames kept as rows (sender number, left, right), from ``m``
    before the gap to ``m`` after it (``frames_around``); inf where one was not kept (None): the
    streamed judge's ``SkipCounts`` and the live judge's ``livegapskips.LiveGapSkips``."""
    if not rows or any(row is None for row in rows):
        return math.inf
    seq, left, right = (np.array(col, dtype=np.int64) for col in zip(*rows, strict=True))
    return skip_allowance_m(left, right, seq, geometry, bits, integrator)


def skipped_at(enc: Encoders, b: int, m: int | None, geometry: Geometry, bits: int,
               integrator: str) -> float:
    """The whole-log judge's ``skip_allowance_m`` of the gap into ``enc``'s frame ``b``
    (``m``: ``Seen.skipped``; inf where it is None or the frames lie beyond ``enc``)."""
    if m is None:
        return math.inf
    first, end = frames_around(b, m)
    if first < 0 or end > len(enc.seq):
        return math.inf
    return skip_allowance_m(enc.left[first:end], enc.right[first:end], enc.seq[first:end],
                            geometry, bits, integrator)


def took_none(seen: Seen, reprimed: frozenset[int]) -> Callable[[int], bool]:
    """Whether the pages prove the firmware took none of the frames the gap into encoder frame
    ``b`` lacks: it missed them too (``Seen.gap_missed``), or it received exactly the log's
    frames around the gap (``Seen.skipped``: not None). Its path across the gap then grew by at
    most the reference's (``distance``: no gap path above; the whole-log and streamed judge's)."""
    return lambda b: seen.gap_missed(b, reprimed) or seen.skipped(b, reprimed) is not None
