"""A real-time fleet run (``run_fleet``) that drives until the test saw what it checks, and a
fleet clock paced by the wall clock that is never late (``PacedClock``).

A test that gave the fleet 1.5 s of wall time and then read what its bridge had published
depended on the machine's load: with the loop stalled 1.4 s at the first tick (CI measured
1.1 s), the run ended before the bridge had published a reference or an error. Here the fleet's
own stop (what SIGINT/SIGTERM set, ``fleetrun._paced``) is also set by ``seen``; the run's
``duration_s`` only bounds a hang.

A fleet tick ``sim.board.HALT_AFTER_S`` (95 ms) late halts every board (a halted MCU's: TIME_LOST,
DEGRADED, frames lost, the judges from then on stretch by stretch, ``host.mqtt.overload``), as it
must; a test of something else (the monitor's table, a status's verdict, SecOC answers) then
failed on a loaded machine (a 1.4 s stall at the first tick: DEGRADED for OK, "no sample wrong
before the loop first halted the robot" for the correct firmware's PASS and the wrong one's
FAIL). ``PacedClock`` keeps the pacing and stops the fleet's time while the process stalls.
"""

from __future__ import annotations

import asyncio
import time
from typing import Any

import pytest

from odocan.host.mqtt import fleetrun
from odocan.sim import fleet as sim_fleet
from odocan.sim.board import TICK_S
from odocan.sim.fleet import run_realtime  # the one fleetrun calls

BOUND_S = 60.0  # the fleet's duration_s where it stops once the test saw what it checks


def stop_fleet_when(monkeypatch: pytest.MonkeyPatch, seen: asyncio.Event) -> None:
    """The next ``run_fleet``'s clock stops (as at a signal) once ``seen`` is set."""

    async def until_seen(*args: Any, stop: asyncio.Event, **kwargs: Any) -> Any:
        async def stop_when_seen() -> None:
            await seen.wait()
            stop.set()

        watcher = asyncio.create_task(stop_when_seen(), name="test-stop-when-seen")
        try:
            return await run_realtime(*args, stop=stop, **kwargs)
        finally:
            watcher.cancel()

    monkeypatch.setattr(fleetrun, "run_realtime", until_seen)


class PacedClock:
    """``sim.fleet.run_realtime``'s clock, paced by the wall clock and never late: tick k waits
    for its release (the first of its two reads, the wall clock's time), and a tick that came
    late moves the clock's origin by its lateness (the second read says its release). The
    fleet's time stops while the process stalls, as a lockstep rig's would."""

    def __init__(self) -> None:
        self.origin_s = time.monotonic()
        self.reads = 0

    def now_s(self) -> float:
        self.reads += 1
        now_s = time.monotonic() - self.origin_s
        if self.reads % 2:  # before tick k's release: wait for it
            return now_s
        release_s = (self.reads // 2 - 1) * TICK_S
        self.origin_s += max(now_s - release_s, 0.0)
        return release_s


def pace_never_late(monkeypatch: pytest.MonkeyPatch) -> None:
    """Every fleet run of the test on a ``PacedClock``."""
    monkeypatch.setattr(sim_fleet, "RealTimeClock", PacedClock)
