"""The rotation fit's sums (``reference_path._rotation_fit``, ``stream_fit``): a dot product in
fixed blocks a log read in chunks can sum alike, and values centred on their segment's mean.
Moved out of ``reference_path`` (its 500 lines)."""

from __future__ import annotations

import numpy as np

from odocan.host.judge.samples import FloatArray, IntArray

DOT_BLOCK = 1 << 16  # samples per block of the rotation fit's sums (22 min at 50 Hz)


def block_dot(a: FloatArray, b: FloatArray) -> float:
    """``np.dot(a, b)`` taken in blocks of ``DOT_BLOCK`` elements aligned on element 0, the
    blocks' dots added in order: what a log read in chunks can sum too, whatever the chunking
    (``host.judge.stream_fit.BlockDot``). One block (up to 22 min of samples): ``np.dot``."""
    total = float(np.dot(a[:DOT_BLOCK], b[:DOT_BLOCK]))
    for start in range(DOT_BLOCK, len(a), DOT_BLOCK):
        total += float(np.dot(a[start : start + DOT_BLOCK], b[start : start + DOT_BLOCK]))
    return total


def centred(values: FloatArray, segment: IntArray) -> FloatArray:
    """``values`` less the mean of their segment."""
    sums = np.bincount(segment, weights=values)
    counts = np.maximum(np.bincount(segment), 1)
    out: FloatArray = values - (sums / counts)[segment]
    return out
