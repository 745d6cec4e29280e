"""The allowance of a stall's or hold's break whose span holds gaps the log fills (issue #11,
rule 5; ``host.judge.gapfill``), shared by the whole-log, the streamed and the live judge.

``breaks.overlap_allowance_m`` bounds such a span as if its gaps' frames were unknown: the
gap allowance of the whole span (``gapbound``'s worst split of its travel, 0.6 m on pmir over
18 periods). But when every frame its gaps lack was heard refused with its CRC right, the
sender's counts at every period of the span are known, and ``gapfill``'s argument holds for
the span as for one gap: the firmware took some of those frames in sequence order (its E2E
never takes one behind one it took), the reference the log's accepted ones, so each is within
the merge allowance over the known frames of the fine path, and the break's allowance is
twice it (``gapfill.known_counts_allowance_m``).

This is the case of a capture whose stamps are a few ms late (``e2e_periods``'
CAPTURE_TOLERANCE_CYCLES): after a late frame the firmware's E2E lock-out refuses the on-time
frames until its COUNTER comes round, but the host's window, widened by the tolerance, takes a
few of them; the firmware holds its pose over them (a hold: ``stalls._frozen``), and the
break's span holds the lock-out's gaps before and after them. With ``gapbound``'s allowance
there a firmware adding 1 mm of X after each lock-out passed the whole-log judge
(tests/test_live_jitter_lockout.py)."""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from odocan.host.judge.breaks import MAX_MERGE_FRAMES
from odocan.host.judge.gapfill import Counts, known_counts_allowance_m
from odocan.host.judge.reference import Geometry, SpeedBound
from odocan.host.judge.samples import IntArray

Fills = Callable[[int], list[Counts] | None]  # per frame k of a span: the gap into it's frames


def span_counts(left: IntArray, right: IntArray, seq: IntArray, fills: Fills
                ) -> tuple[IntArray, IntArray] | None:
    """The counts of every sender period of a span: its accepted frames' (``left``, ``right``,
    sender numbers ``seq``) with, before each frame k after a gap, the counts of the frames
    that gap lacks (``fills(k)``); None when one is not filled (or not period for period)."""
    full_left, full_right = [int(left[0])], [int(right[0])]
    for k in range(1, len(seq)):
        missing = int(seq[k] - seq[k - 1]) - 1
        if missing < 0:
            return None
        if missing:
            filled = fills(k)
            if filled is None or len(filled) != missing:
                return None
            full_left += [c[0] for c in filled]
            full_right += [c[1] for c in filled]
        full_left.append(int(left[k]))
        full_right.append(int(right[k]))
    return np.array(full_left, dtype=np.int64), np.array(full_right, dtype=np.int64)


def filled_span_allowance_m(
    left: IntArray, right: IntArray, seq: IntArray, fills: Fills, geometry: Geometry,
    bits: int, integrator: str, max_wheel_speed_mm_s: SpeedBound,
) -> float | None:
    """The allowance (m) of a break's span (its accepted frames, first and last included) that
    holds a gap, when the log fills every gap (``span_counts``) with plausible steps; None
    otherwise, and for a span of more than ``breaks.MAX_MERGE_FRAMES`` accepted frames (the
    streamed judge keeps only their steps' sums: the same answer in both)."""
    if len(seq) - 2 > MAX_MERGE_FRAMES or int(seq[-1] - seq[0]) == len(seq) - 1:
        return None
    full = span_counts(left, right, seq, fills)
    if full is None:
        return None
    return known_counts_allowance_m(*full, geometry, bits, integrator, max_wheel_speed_mm_s)
