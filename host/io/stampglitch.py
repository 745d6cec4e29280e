"""A frame whose stamp is far off both its neighbours, its neighbours in order: a glitched stamp
(one bad clock reading, a bit flipped in a stored time), set aside by the log's readers
(``host.io.logs``: ``read_log`` and ``iter_log`` alike, so the whole and the streamed analyses
judge the same frames).

Kept, one such stamp sized what the judges derive from time: a frame 1e8 s ahead of a 5 s
drive made a "silence" of 1e10 encoder periods (``analyze`` past 5 GB), and 1000 s ahead it
FAILed a correct drive (a 998.7 s silence, a re-prime, the distance 1.6 mm off; trial40).
It cannot be a reorder: a recorder's stamping goes back by ``STAMPING_S`` at most, and a frame
held back on the bus is logged in bus order; nor a pause (a recorder paused and resumed is
monotonic: the frames after it follow the jump, they do not come back). Its time is unknown
(its place in the log says only "between its neighbours"), and the judges read times; so it is
set aside, not re-stamped: the judges see a frame lost, a gap of the log they bound as any.
One warning names the log, the frame (its number among the log's frames) and its stamp.
The rule is ``host.io.stamprule``'s, the live judges' too (``host.judge.livestampgate``).

At most ``MAX_SET_ASIDE`` frames (the first): a log with more such frames is no glitch but two
clocks interleaved (merged logs) or a shuffle, left as recorded (``TimeOrder`` says so).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Iterator
from pathlib import Path

import numpy as np
import numpy.typing as npt

from odocan.host.io.frames import FrameArrays, concat_frames
from odocan.host.io.stamprule import MAX_SET_ASIDE, lone, set_aside_text

FloatArray = npt.NDArray[np.float64]


def lone_stamps(times_s: FloatArray, before_s: float, after_s: float) -> npt.NDArray[np.intp]:
    """Positions of the frames of ``times_s`` whose stamp is more than ``JUMP_S`` off both
    neighbours in one direction, the neighbours in order (the frame before the first at
    ``before_s``, after the last at ``after_s``; nan: none, no such frame there)."""
    if len(times_s) == 0:
        return np.zeros(0, np.intp)
    prev_s = np.concatenate(([before_s], times_s[:-1]))
    next_s = np.concatenate((times_s[1:], [after_s]))
    with np.errstate(invalid="ignore"):
        return np.flatnonzero(lone(prev_s, times_s, next_s))  # (stamprule: the live gate's)


class StampGlitches:
    """The frames of a log, fed in order a part at a time, less the glitched stamps
    (``through``); ``report`` says what was set aside."""

    def __init__(self) -> None:
        self.count = 0
        self.frames = 0  # frames passed on or held
        self.first: tuple[int, float, float, float] | None = None  # number, stamp, prev, next
        self._held: FrameArrays | None = None  # the last frame, its next not seen yet
        self._before_s = math.nan  # the stamp of the frame before the held one

    def whole(self, frames: FrameArrays) -> FrameArrays:
        """``frames`` (a whole log) less its glitched stamps (the same as ``through``)."""
        self.frames = len(frames)
        lone = self._take(lone_stamps(frames.timestamp_s, math.nan, math.nan),
                          frames.timestamp_s, math.nan, math.nan, 0)
        if not len(lone):
            return frames
        keep = np.ones(len(frames), np.bool_)
        keep[lone] = False
        return frames.select(keep)

    def through(self, parts: Iterable[FrameArrays]) -> Iterator[FrameArrays]:
        """The frames of ``parts`` less their glitched stamps, one frame held to the next part
        (its next neighbour)."""
        for part in parts:
            if len(part) == 0:
                continue
            ext = part if self._held is None else concat_frames([self._held, part])
            first = self.frames - (0 if self._held is None else 1)  # ext[0]'s index in the log
            self.frames += len(part)
            times = ext.timestamp_s
            lone = self._take(lone_stamps(times[:-1], self._before_s, float(times[-1])),
                              times, self._before_s, float(times[-1]), first)
            self._before_s = float(times[-2]) if len(times) > 1 else self._before_s
            self._held = ext.select(slice(len(ext) - 1, None))
            keep = np.ones(len(ext) - 1, np.bool_)
            keep[lone] = False
            yield ext.select(slice(0, len(ext) - 1)) if not len(lone) else (
                ext.select(np.flatnonzero(keep)))
        if self._held is not None:
            yield self._held
            self._held = None

    def _take(self, lone: npt.NDArray[np.intp], times_s: FloatArray, before_s: float,
              after_s: float, first: int) -> npt.NDArray[np.intp]:
        """The first of ``lone`` up to ``MAX_SET_ASIDE`` in all, accounted."""
        lone = lone[:max(0, MAX_SET_ASIDE - self.count)]
        if len(lone) and self.first is None:
            k = int(lone[0])
            prev_s = float(times_s[k - 1]) if k > 0 else before_s
            next_s = float(times_s[k + 1]) if k + 1 < len(times_s) else after_s
            self.first = (first + k + 1, float(times_s[k]), prev_s, next_s)
        self.count += len(lone)
        return lone

    def report(self, path: Path, warn: Callable[[str], None]) -> None:
        """One warning when any frame was set aside."""
        if self.first is None:
            return
        warn(f"{path}: {set_aside_text(self.count, *self.first)}")
