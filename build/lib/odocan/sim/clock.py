"""Clocks: simulated lockstep time, or the wall clock for real-time nodes.

Every frame a node sends is stamped with its clock's ``now_s()``. A lockstep clock only moves when
the rig advances it, so the same seed gives the same timestamps and the same bytes.
"""

from __future__ import annotations

import time
from typing import Protocol


class Clock(Protocol):
    """What nodes need of time."""

    def now_s(self) -> float:
        """Seconds since the start of the run."""
        ...


class LockstepClock:
    """Simulated time, advanced explicitly by the rig."""

    def __init__(self, start_s: float = 0.0) -> None:
        self._now_s = start_s

    def now_s(self) -> float:
        """The simulated time (s)."""
        return self._now_s

    def advance_to(self, t_s: float) -> None:
        """Move simulated time forward to ``t_s``."""
        self._now_s = t_s


class RealTimeClock:
    """Monotonic wall-clock time since construction; ``sleep_until`` paces a periodic loop."""

    def __init__(self) -> None:
        self._start = time.monotonic()

    def now_s(self) -> float:
        """Seconds since the clock started (monotonic)."""
        return time.monotonic() - self._start

    def sleep_until(self, t_s: float) -> float:
        """Sleep until ``t_s``; returns how late we already were (s, >= 0) when called."""
        delay = t_s - self.now_s()
        if delay > 0:
            time.sleep(delay)
            return 0.0
        return -delay
