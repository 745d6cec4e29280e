"""A real-time fleet's releases, shared with the work that runs between them (issue #13).

A fleet worker is one thread: its clock task steps every robot at each release ``k * period``,
and the MQTT bridge judges and publishes in the loop's turns between. A tick is late when the
loop is busy at its release: a bridge slice started just before it runs to its end first.

- ``ReleaseGate``: the next release on the monotonic clock (set by ``sim.fleet.run_realtime``).
  Work that can wait (the bridge's slices, its periodic publications) asks ``hold_s`` before it
  starts, and starts none within ``margin_s`` of a release: it sleeps until just after it, so the
  release finds the loop free. A release that work overran (a slice started just outside the
  margin and ran past it) is not left behind more work: until its tick has run, work that would
  start within half a period after it waits for the tick (``clear``). Without that, the tick
  waited for every handle the event loop had queued before its timer fired and for the one
  after (two or three more slices, ~2 ms each at 50 robots): most late ticks of a 100-robot
  fleet were a release overrun by under a millisecond, then 5-6 ms of slices (the per-tick
  trace, ``host.mqtt.ticktrace``).
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
OVERRUN_S = 0.005  # half a 10 ms period: a release past by more is late anyway (not waited for)


class ReleaseGate:
    """The next release (monotonic seconds, ``next_s``; None before the clock starts)."""

    def __init__(self, margin_s: float = GATE_MARGIN_S,
                 clock: Callable[[], float] = time.monotonic,
                 overrun_s: float = OVERRUN_S) -> None:
        self.margin_s = margin_s
        self.overrun_s = overrun_s
        self._next_s: float | None = None
        self._told: asyncio.Future[None] | None = None  # resolved when the next release is told
        self.holds = 0  # how many times work waited for a release (the bridge's counters)
        self.overruns = 0  # of them, how many waited for an overrun release's tick
        self._clock = clock

    @property
    def next_s(self) -> float | None:
        """The next release; told by the clock before it waits for it, once the previous
        release's tick has run (which wakes the work waiting for that tick)."""
        return self._next_s

    @next_s.setter
    def next_s(self, release_s: float | None) -> None:
        self._next_s = release_s
        if self._told is not None:
            if not self._told.done():
                self._told.set_result(None)
            self._told = None

    def hold_s(self) -> float:
        """How long work about to start should wait: until just after the next release when that
        is less than ``margin_s`` ahead, else 0. A release already past is not waited for: its
        tick is late anyway, and a loop that runs behind (an overloaded machine: every release
        past when the last tick ends) would otherwise give the bridge a slice per tick only."""
        if self._next_s is None:
            return 0.0
        left_s = self._next_s - self._clock()
        return left_s + AFTER_RELEASE_S if 0.0 <= left_s < self.margin_s else 0.0

    def overrun(self) -> bool:
        """The release is past by less than ``overrun_s`` and its tick has not run (the clock
        has not told the next one): work overran it, and the tick can still be on time."""
        if self._next_s is None:
            return False
        return -self.overrun_s <= self._next_s - self._clock() < 0.0

    async def clear(self) -> None:
        """Return once no release is within ``margin_s`` (at once, most often), and no
        overrun release's tick is still to run (``overrun``; waited for at most ``overrun_s``)."""
        wait_s = self.hold_s()
        if wait_s > 0.0:
            self.holds += 1
            await asyncio.sleep(wait_s)
        elif self.overrun():
            self.holds += 1
            self.overruns += 1
            if self._told is None:
                self._told = asyncio.get_running_loop().create_future()
            await asyncio.wait([self._told], timeout=self.overrun_s)

    async def sleep(self, delay_s: float) -> None:
        """``asyncio.sleep(delay_s)``, then ``clear``: a periodic task's pace, gated."""
        await asyncio.sleep(delay_s)
        await self.clear()


def phased_start_s(epoch_s: float, fraction: float, period_s: float, now_s: float) -> float:
    """The first instant at or after ``now_s`` that lies ``fraction`` of a period past
    ``epoch_s`` (mod ``period_s``): where a worker's clock starts (monotonic seconds)."""
    offset_s = (now_s - epoch_s - fraction * period_s) % period_s
    return now_s if offset_s == 0.0 else now_s + period_s - offset_s
