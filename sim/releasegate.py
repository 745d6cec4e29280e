"""A real-time fleet's releases, shared with the work that runs between them (issue #13).

A fleet worker is one thread: its clock task steps every robot at each release ``k * period``,
and the MQTT bridge judges and publishes in the loop's turns between. A tick is late when the
loop is busy at its release: a bridge slice started just before it runs to its end first.

- ``ReleaseGate``: the next release on the monotonic clock (set by ``sim.fleet.run_realtime``).
  Work that can wait (the bridge's slices, its periodic publications) asks ``hold_s`` before it
  starts, and starts none within ``margin_s`` of a release: it sleeps until just after it, so the
  release finds the loop free.
- ``phased_start_s``: where a worker's clock starts. The workers of one machine start their
  clocks a fraction of a period apart on the shared monotonic clock (worker ``w`` of ``n`` at
  ``w / n`` of a period past a common epoch): their steps, and the broker's bursts that follow,
  do not fall on the two cores at once. Without it each worker's phase is wherever its start-up
  ended.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Callable

GATE_MARGIN_S = 0.0015  # a bridge slice (8 frames taken) judges up to ~1.5 ms of frames
AFTER_RELEASE_S = 0.0002  # the held work wakes this long after the release: the tick goes first


class ReleaseGate:
    """The next release (monotonic seconds, ``next_s``; None before the clock starts)."""

    def __init__(self, margin_s: float = GATE_MARGIN_S,
                 clock: Callable[[], float] = time.monotonic) -> None:
        self.margin_s = margin_s
        self.next_s: float | None = None
        self.holds = 0  # how many times work waited for a release (the bridge's counters)
        self._clock = clock

    def hold_s(self) -> float:
        """How long work about to start should wait: until just after the next release when that
        is less than ``margin_s`` ahead, else 0. A release already past is not waited for: its
        tick is late anyway, and a loop that runs behind (an overloaded machine: every release
        past when the last tick ends) would otherwise give the bridge a slice per tick only."""
        if self.next_s is None:
            return 0.0
        left_s = self.next_s - self._clock()
        return left_s + AFTER_RELEASE_S if 0.0 <= left_s < self.margin_s else 0.0

    async def clear(self) -> None:
        """Return once no release is within ``margin_s`` (at once, most often)."""
        wait_s = self.hold_s()
        if wait_s > 0.0:
            self.holds += 1
            await asyncio.sleep(wait_s)

    async def sleep(self, delay_s: float) -> None:
        """``asyncio.sleep(delay_s)``, then ``clear``: a periodic task's pace, gated."""
        await asyncio.sleep(delay_s)
        await self.clear()


def phased_start_s(epoch_s: float, fraction: float, period_s: float, now_s: float) -> float:
    """The first instant at or after ``now_s`` that lies ``fraction`` of a period past
    ``epoch_s`` (mod ``period_s``): where a worker's clock starts (monotonic seconds)."""
    offset_s = (now_s - epoch_s - fraction * period_s) % period_s
    return now_s if offset_s == 0.0 else now_s + period_s - offset_s
