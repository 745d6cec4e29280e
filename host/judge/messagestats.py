"""One DBC message as the monitor knows it (``host.judge.monitor``): count, rate and the period
jitter over the last ``RATE_WINDOW`` frames (bus timestamps), the latest signal values, and for a
multiplexed message the same per page (pages sent together have no common period)."""

from __future__ import annotations

import statistics
from collections import deque
from dataclasses import dataclass, field
from itertools import pairwise
from typing import Any

RATE_WINDOW = 128  # frames per message for rate and jitter (1.28 s of WHEEL_ENCODERS)


@dataclass
class MessageStats:
    """What the monitor knows of one DBC message."""

    name: str
    frame_id: int
    count: int = 0
    times: deque[float] = field(default_factory=lambda: deque(maxlen=RATE_WINDOW))
    last: dict[str, Any] = field(default_factory=dict)  # every signal's latest value
    last_frame: dict[str, Any] = field(default_factory=dict)  # the latest frame's signals
    heard_monotonic_s: float = 0.0
    pages: dict[str, MessageStats] = field(default_factory=dict)  # per multiplexer value

    def heard(self, timestamp_s: float, now_s: float, page: str | None = None) -> None:
        """Count one frame of this message (bus timestamp, local monotonic time, its page)."""
        self.count += 1
        self.times.append(timestamp_s)
        self.heard_monotonic_s = now_s
        if page is not None:
            stats = self.pages.get(page)
            if stats is None:
                stats = self.pages[page] = MessageStats(page, self.frame_id)
            stats.heard(timestamp_s, now_s)

    def timing(self) -> dict[str, Any]:
        """``count``, ``rate_hz``, ``jitter_ms``."""
        return {"count": self.count, "rate_hz": self.rate_hz(), "jitter_ms": self.jitter_ms()}

    def rate_hz(self) -> float | None:
        """Frames per second over the window (None before two frames)."""
        if len(self.times) < 2 or self.times[-1] <= self.times[0]:
            return None
        return (len(self.times) - 1) / (self.times[-1] - self.times[0])

    def jitter_ms(self) -> float | None:
        """Standard deviation of the inter-frame period over the window (ms)."""
        if len(self.times) < 3:
            return None
        return 1e3 * statistics.pstdev(b - a for a, b in pairwise(self.times))
