"""A real-time fleet run (``run_fleet``) that drives until the test saw what it checks.

A test that gave the fleet 1.5 s of wall time and then read what its bridge had published
depended on the machine's load: with the loop stalled 1.4 s at the first tick (CI measured
1.1 s), the run ended before the bridge had published a reference or an error. Here the fleet's
own stop (what SIGINT/SIGTERM set, ``fleetrun._paced``) is also set by ``seen``; the run's
``duration_s`` only bounds a hang.
"""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from odocan.host.mqtt import fleetrun
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
