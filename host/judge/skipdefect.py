"""How much shorter the firmware's path may be where it took fewer of the log's encoder frames
than the host did (``losses.ok_count_spans``: its ENC_E2E_OK grew by n less between two pages),
for ``distance.DistanceJudge`` (issue #11, rule 5), fed frame by frame in one call or chunk by
chunk with the same result bit for bit.

A frame the firmware did not take merges its step with the next one: for a run of skipped
frames, the steps dS_1..dS_m+1 (signed, m along the wheel-axis midpoint) into the run's frames
and the one after become one, and the path grows by |sum dS_i| instead of sum |dS_i|: shorter by
the run's *defect* sum |dS_i| - |sum dS_i| (0 unless the midpoint reverses inside it). n frames
skipped among the span's frames (a, z] make at most n runs, each of at most n + 1 consecutive
steps into frames (a, z + 1]: the path up to frame j is shorter by at most n times the largest
defect of such a window ending at or before j (``SkipDown.feed``). Past ``MAX_RUN`` frames
skipped, the span's whole fine path (sum |dS| of its steps up to j) bounds it. Which frames the
firmware took instead is unknown (the count is net: a frame it took that the host refused
hides one it skipped; not modelled, see ``losses.ok_count_spans``).

The steps are summed in whole 2^-40 m (int64, as ``distance`` sums the reference), so the sums
are exact and chunking cannot change them; the rounding moves a window's defect by at most
(n + 1) 2^-40 m, below 3e-10 m for ``MAX_RUN``: inside the wire's 1e-9 m float slack."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from odocan.host.judge.samples import FloatArray, IntArray

MAX_RUN = 16  # frames skipped in a span beyond which its fine path bounds the defect
UNITS_PER_M = float(1 << 40)  # the steps' unit: 2^-40 m


@dataclass
class SkipDown:
    """The allowance (m, cumulative over frames) for ``spans`` (first, last, n): ``feed`` the
    frames in order (consecutive numbers) with the signed step into each."""

    spans: list[tuple[int, int, int]]
    _tail: tuple[IntArray, IntArray, IntArray] | None = None  # last frames: g, S, |S| sums
    _best: dict[int, int] = field(default_factory=dict)  # span: its largest defect (2^-40 m)
    _anchor: dict[int, int] = field(default_factory=dict)  # span: sum |dS| at its first frame

    def feed(self, g: IntArray, ds_m: FloatArray) -> FloatArray:
        """Per frame ``g``: the allowance (m) at it, the spans' so far summed."""
        s0, a0 = (0, 0) if self._tail is None else (int(self._tail[1][-1]),
                                                     int(self._tail[2][-1]))
        units = np.rint(ds_m * UNITS_PER_M).astype(np.int64)
        signed, absolute = s0 + np.cumsum(units), a0 + np.cumsum(np.abs(units))
        if self._tail is not None:
            g, signed, absolute = (np.concatenate((old, new)) for old, new in
                                   zip(self._tail, (g, signed, absolute), strict=True))
        fresh = len(g) - len(ds_m)  # the carried frames before this chunk's
        total = np.zeros(len(ds_m))
        for key, (a, z, n) in enumerate(self.spans):
            if z + 1 < int(g[fresh]):  # done before this chunk
                total += (n if n <= MAX_RUN else 1) * self._best.get(key, 0) / UNITS_PER_M
            elif a <= int(g[-1]):
                total += self._span_down(key, (a, z, n), g, signed, absolute)[fresh:]
        keep = max(0, len(g) - MAX_RUN - 2)
        self._tail = (g[keep:], signed[keep:], absolute[keep:])
        return total

    def _span_down(self, key: int, span: tuple[int, int, int], g: IntArray, signed: IntArray,
                   absolute: IntArray) -> FloatArray:
        """One span's allowance at each frame of ``g`` (consecutive, its carried frames first)."""
        a, z, n = span
        g0 = int(g[0])
        i0, i1 = max(0, a - g0), max(0, min(len(g), z + 2 - g0))
        if 0 <= a - g0 < len(g) and key not in self._anchor:
            self._anchor[key] = int(absolute[a - g0])
        out = np.zeros(len(g), dtype=np.int64)
        if i0 >= i1:
            out[max(i1, a + 1 - g0, 0):] = self._best.get(key, 0)
            return (n if n <= MAX_RUN else 1) * out / UNITS_PER_M
        sig, ab = signed[i0:i1], absolute[i0:i1]
        defect = np.zeros(i1 - i0, dtype=np.int64)
        if n > MAX_RUN:  # the fine path since the span's first frame
            defect = ab - self._anchor.get(key, int(absolute[0]))
        else:
            for w in range(2, n + 2):
                if w < len(ab):
                    defect[w:] = np.maximum(defect[w:], ab[w:] - ab[:-w]
                                            - np.abs(sig[w:] - sig[:-w]))
        best = np.maximum.accumulate(np.maximum(defect, self._best.get(key, 0)))
        self._best[key] = int(best[-1])
        out[i0:i1] = best
        out[i1:] = best[-1]
        out[: max(0, a + 1 - g0)] = 0
        return (n if n <= MAX_RUN else 1) * out / UNITS_PER_M
