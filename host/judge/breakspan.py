"""The allowance of one stall's or hold's break in the whole-log judge (``host.judge.breaks``
module docstring): its span runs from the frame before the break (the last the firmware named)
to the first frame a kept sample names at or after it; ``reference_path.build_reference`` places
the segment the break opens within it."""

from __future__ import annotations

import numpy as np

from odocan.host.judge.breaks import merge_allowance_m, overlap_allowance_m
from odocan.host.judge.gapseen import Seen
from odocan.host.judge.reference import PROFILE_SPEED, Geometry, SpeedBound
from odocan.host.judge.samples import Encoders, IntArray
from odocan.host.judge.spanfill import Fills, filled_span_allowance_m


def break_allowance(enc: Encoders, b: int, sample_enc: IntArray, geometry: Geometry, bits: int,
                    integrator: str, *, max_wheel_speed_mm_s: SpeedBound = PROFILE_SPEED,
                    fills: Fills | None = None) -> float:
    """``breaks.merge_allowance_m`` of the break at encoder frame ``b``: from frame b - 1 (the
    last the firmware named before it) to the first frame a kept sample names at or after b (0
    without one: nothing after it is compared); plus ``breaks.overlap_allowance_m`` when a gap
    of the log lies in that span, unless the log fills every such gap (``fills``: per encoder
    frame, the counts of the frames the gap into it lacks, ``gapseen.Seen.filled``): then
    ``spanfill.filled_span_allowance_m``."""
    k = int(np.searchsorted(sample_enc, b))
    if k == len(sample_enc):
        return 0.0
    j = int(sample_enc[k])
    if fills is not None:
        filled = filled_span_allowance_m(
            enc.left[b - 1 : j + 1], enc.right[b - 1 : j + 1], enc.seq[b - 1 : j + 1],
            lambda i: fills(b - 1 + i), geometry, bits, integrator, max_wheel_speed_mm_s)
        if filled is not None:
            return filled
    ends = [(int(enc.seq[i]), int(enc.left[i]), int(enc.right[i])) for i in (b - 1, j)]
    return merge_allowance_m(enc.left[b - 1 : j + 1], enc.right[b - 1 : j + 1], geometry, bits,
                             integrator, enc.seq[b - 1 : j + 1]) + overlap_allowance_m(
        ends[0], ends[1], j - b + 2, geometry, bits, integrator, max_wheel_speed_mm_s)


def seen_whole(seen: Seen, b: int, sample_enc: IntArray, reprimed: frozenset[int]) -> bool:
    """Whether the firmware took exactly the log's frames across the break at encoder frame
    ``b`` (``break_allowance``'s span: frame b - 1 to the first frame a kept sample names at or
    after b), as its E2E pages prove (``host.judge.gapseen``): then it took the reference's
    steps there and the break earns no allowance."""
    k = int(np.searchsorted(sample_enc, b))
    return k < len(sample_enc) and seen.took_all(b - 1, int(sample_enc[k]), reprimed)
