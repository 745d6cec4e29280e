"""The three readings' MaxDeltaCounter windows of ``e2e_evidence.settle``, at any frame, without
a step per frame.

``settle`` widened each reading's window at every frame, ``min(w + periods, 15)``, and set all
three to ``MaxDeltaCounterInit`` at each frame taken: a list built per frame, the frames with a
bad CRC included (a live hold's context has hundreds, its CRCs broken on purpose), 9 % of a live
judge's time on a ``delay=0.5:150`` drive. With periods of 0 or more (receive periods and
rounded gaps are: ``e2e_periods``), ``min(min(w + a, 15) + b, 15) == min(w + a + b, 15)``, so a
window is ``min(start + sum of the periods since the reset, 15)``: read from running sums where
a frame is judged, in integers, the same numbers. A column with a period below 0 (no reading
gives one; a NaN stamp would) is stepped frame by frame as before.
"""

from __future__ import annotations

from itertools import accumulate

from odocan.host.protocol.busfacts import ENC_COUNTER_MASK

MAX_WINDOW = ENC_COUNTER_MASK  # 15: Profile 2's widest window, a lap less one


class Windows:
    """The windows of the three readings (``columns``: each one's periods per frame)."""

    __slots__ = ("_at", "_base", "_columns", "_start", "_stepped", "sums")

    def __init__(self, columns: list[list[int]]) -> None:
        self._columns = columns
        self.sums = [list(accumulate(c)) for c in columns]  # periods up to each frame (exact)
        self._stepped = any(c and min(c) < 0 for c in columns)  # (never, but kept exact)
        self._start = 0  # each window at the last reset (none yet: 0)
        self._base = -1  # the frame of the last reset (-1: none, the sums start at 0)
        self._at = (-1, [0, 0, 0])  # stepped: the frame reached and the windows there

    def at(self, j: int) -> list[int]:
        """The three windows at frame ``j`` (its periods added), ``j`` after the last reset."""
        if self._stepped:
            return self._step_to(j)
        start, base = self._start, self._base
        if base < 0:
            return [min(start + s[j], MAX_WINDOW) for s in self.sums]
        return [min(start + s[j] - s[base], MAX_WINDOW) for s in self.sums]

    def reset(self, j: int, start: int) -> None:
        """Frame ``j`` taken: each window restarts at ``start`` after it."""
        self._start, self._base = start, j
        if self._stepped:
            self._at = (j, [start] * 3)

    def _step_to(self, j: int) -> list[int]:
        """The windows at ``j`` widened frame by frame (``settle``'s rule as written)."""
        k, windows = self._at
        for q in range(k + 1, j + 1):
            windows = [min(w + c[q], MAX_WINDOW)
                       for w, c in zip(windows, self._columns, strict=True)]
        self._at = (j, windows)
        return windows

