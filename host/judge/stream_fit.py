"""The start fit's sums chunk by chunk (issue #14.1): the rotation fit of
``host.judge.reference_path`` sums over every on-board sample, and a sum taken in chunks is the
whole log's only if its additions are the same, in the same order:

* ``SegmentSums``: the per-segment sums of ``np.bincount(segment, weights=values)`` (one
  addition after the other from 0.0, in sample order: the carried sum of the open segment is
  continued with ``np.cumsum``, which adds in the same order), and the counts: the segment
  means of ``blockdot.centred``;
* ``BlockDot``: ``blockdot.block_dot``, the dot product in fixed blocks of
  ``DOT_BLOCK`` samples aligned on the first sample: a block's dot is taken when its last
  sample arrives (the block waits, at most ``DOT_BLOCK`` values per operand), the blocks' dots
  added in order.

Both are exact at any chunk size (tests/test_stream_facts.py)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from odocan.host.judge.blockdot import DOT_BLOCK

FloatArray = npt.NDArray[np.float64]


@dataclass
class SegmentSums:
    """Sums and counts of values per segment (segments numbered from 0, non-decreasing)."""

    sums: FloatArray = field(default_factory=lambda: np.zeros(0))
    counts: npt.NDArray[np.int64] = field(default_factory=lambda: np.zeros(0, dtype=np.int64))

    def feed(self, segment: npt.NDArray[np.int64], values: FloatArray) -> None:
        """Add the next samples (their segments and values)."""
        if len(segment) == 0:
            return
        top = int(segment[-1]) + 1
        if top > len(self.sums):
            self.sums = np.concatenate((self.sums, np.zeros(top - len(self.sums))))
            self.counts = np.concatenate(
                (self.counts, np.zeros(top - len(self.counts), dtype=np.int64)))
        first = int(segment[0])
        head = segment == first  # the open segment: continued from its carried sum
        carried = np.concatenate(([self.sums[first]], values[head]))
        self.sums[first] = np.cumsum(carried)[-1]
        self.counts[first] += int(np.count_nonzero(head))
        rest = ~head
        if rest.any():  # segments starting in this chunk: summed from 0.0 like the whole log
            part = np.bincount(segment[rest] - first, weights=values[rest])
            self.sums[first + 1 : first + len(part)] = part[1:]
            self.counts[first + 1 : first + len(part)] = np.bincount(segment[rest] - first)[1:]

    def means(self) -> FloatArray:
        """``sums / max(counts, 1)``, as ``blockdot.centred`` takes them."""
        means: FloatArray = self.sums / np.maximum(self.counts, 1)
        return means


@dataclass
class BlockDot:
    """``blockdot.block_dot`` of two operands given chunk by chunk."""

    total: float | None = None
    _a: list[FloatArray] = field(default_factory=list)  # the open block's values
    _b: list[FloatArray] = field(default_factory=list)
    _n: int = 0  # values in the open block

    def feed(self, a: FloatArray, b: FloatArray) -> None:
        """Add the next elements of both operands."""
        while len(a):
            take = min(len(a), DOT_BLOCK - self._n)
            self._a.append(a[:take])
            self._b.append(b[:take])
            self._n += take
            a, b = a[take:], b[take:]
            if self._n == DOT_BLOCK:
                self._close()

    def result(self) -> float:
        """The dot of everything fed (0.0 for nothing)."""
        if self._n or self.total is None:
            self._close()
        assert self.total is not None
        return self.total

    def _close(self) -> None:
        a = np.concatenate(self._a) if self._a else np.zeros(0)
        b = np.concatenate(self._b) if self._b else np.zeros(0)
        dot = float(np.dot(a, b))
        self.total = dot if self.total is None else self.total + dot
        self._a, self._b, self._n = [], [], 0
