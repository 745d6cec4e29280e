"""The streamed evidence of ``powerup.heard_by_tick``: up to the first count page, the latest
accepted summaries' COUNTER and bus time, and the bus times of the latest accepted encoder frames
(with how many came before them), so that the frames before the page's tick bound
(``powerup.tick_bound_s``) are counted as the whole log's judge counts them."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from odocan.host.io.logs import FrameArrays

SUMMARIES_KEPT = 8  # a wrap of the 4-bit ODOM_STATUS COUNTER, two frames a cycle
ENCODERS_KEPT = 128  # 1.28 s of encoder frames at 100 Hz: more than a bound reaches back


@dataclass
class TickTimes:
    """The summaries (COUNTER, bus time) and encoder bus times fed so far, the latest kept."""

    summaries: list[tuple[int, float]] = field(default_factory=list)
    encoder_times_s: npt.NDArray[np.float64] = field(
        default_factory=lambda: np.zeros(0, np.float64))
    dropped: int = 0  # accepted encoder frames fed before ``encoder_times_s``

    def feed(self, chunk: FrameArrays, summary: dict[str, np.ndarray],
             heard: npt.NDArray[np.bool_], encoders: npt.NDArray[np.int64]) -> None:
        """A chunk's accepted summaries before the first count page (``heard``, a mask of
        ``summary``'s rows) and accepted encoder frames before it (``encoders``: positions)."""
        if "COUNTER" in summary and heard.any():
            times = chunk.timestamp_s[summary["index"][heard]].tolist()
            new = list(zip(summary["COUNTER"][heard].tolist(), times, strict=True))
            self.summaries = [*self.summaries, *new][-SUMMARIES_KEPT:]
        stamps = np.concatenate((self.encoder_times_s, chunk.timestamp_s[encoders]))
        self.dropped += max(0, len(stamps) - ENCODERS_KEPT)
        self.encoder_times_s = stamps[-ENCODERS_KEPT:]

    def before(self, bound_s: float, made: int) -> int | None:
        """The accepted encoder frames fed before bus time ``bound_s``, at most ``made``; None
        when those kept all came after it and some were dropped (the count is not known)."""
        kept = int(np.count_nonzero(self.encoder_times_s < bound_s))
        if kept == 0 and self.dropped:
            return None
        return min(self.dropped + kept, made)
