"""A fleet in real time, bridged to MQTT: what ``odocan fleet`` and ``bench/fleet.py`` run.

``run_fleet`` starts N robots (``sim.fleet``), optionally the bridge (one ``RobotLink`` per robot,
the fleet's frames offered to it each tick), runs for ``duration_s`` and returns the report:

```
{"robots": N, "duration_s": ..., "period_s": 0.01, "deadline_miss_ratio": ...,
 "ticks": ..., "late_ticks": ..., "skipped_releases": ..., "max_lateness_ms": ...,
 "broker": "mqtt://127.0.0.1:PORT" | null, "embedded_broker": bool,
 "bridge": {"frames_in": ..., "frames_dropped": ..., "telemetry_dropped": ..., ...} | null,
 "per_robot": {"robot001": {"seed": ..., "frames": {"WHEEL_ENCODERS": ..., ...},
                            "frames_total": ..., "commands_accepted": ...,
                            "commands_rejected": ...}, ...}}
```

``bridge`` holds ``Bridge.counters()``: frames dropped or failed, telemetry dropped (buffer full)
or not kept while offline, QoS-1 publications dropped or refused by the broker, commands expired,
reconnects. A broker that cannot be reached at the start is a ``BrokerError`` (no traceback).

``deadline_miss_ratio`` is the share of 10 ms encoder cycles that started more than half a period
late (``sim.realtime.DeadlineStats``).
"""

from __future__ import annotations

import asyncio
import gc
import signal
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.bridge import Bridge, BridgeConfig, RobotEndpoint
from odocan.host.mqtt.broker import BrokerError, BrokerURL, first_error
from odocan.host.mqtt.options import broker_for
from odocan.sim.fleet import Fleet, FleetConfig, run_realtime
from odocan.sim.realtime import DeadlineStats


@dataclass(frozen=True)
class FleetRun:
    """What to run: the fleet, for how long, and whether (and where) to bridge it."""

    fleet: FleetConfig
    duration_s: float
    bridge: bool = True
    broker: BrokerURL | None = None  # None: an embedded amqtt broker
    publish_hz: float = 10.0
    client_prefix: str = "odocan-bridge"
    connect_timeout_s: float = 5.0
    command_expiry_s: float = 5.0


StartHook = Callable[[int, "BrokerURL | None"], None]


async def run_fleet(run: FleetRun, *, on_start: StartHook | None = None) -> dict[str, Any]:
    """Run the fleet in real time (bridged when ``run.bridge``); returns the report.
    ``on_start(robots, telemetry broker)`` is called when the clock starts (signals handled)."""
    with Fleet(run.fleet) as fleet:
        if not run.bridge:
            stats = await _paced(fleet, run.duration_s, None,
                                 lambda: _started(on_start, fleet, None))
            return _report(run, fleet, stats, None, None, False)
        async with broker_for(run.broker) as (url, embedded):
            bridge = Bridge(_endpoints(fleet, run), config=BridgeConfig(
                broker=url, publish_hz=run.publish_hz, client_prefix=run.client_prefix,
                connect_timeout_s=run.connect_timeout_s, command_expiry_s=run.command_expiry_s))
            stop = asyncio.Event()
            try:
                async with asyncio.TaskGroup() as tg:
                    tg.create_task(bridge.run(stop=stop), name="bridge")
                    await _all_connected(bridge, run.connect_timeout_s + 5.0)
                    stats = await _paced(fleet, run.duration_s, bridge.offer,
                                         lambda: _started(on_start, fleet, url))
                    stop.set()
            except BaseExceptionGroup as group:
                raise first_error(group) from None
            return _report(run, fleet, stats, bridge, url, embedded)


def _started(on_start: StartHook | None, fleet: Fleet, url: BrokerURL | None) -> None:
    if on_start is not None:
        on_start(len(fleet.names), url)


async def _paced(
    fleet: Fleet, duration_s: float, on_batch: Any, started: Callable[[], None]
) -> DeadlineStats:
    """Run the fleet until ``duration_s`` or SIGINT/SIGTERM, whichever comes first: a signal ends
    the run like its duration does, so the report is still written."""
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    handled = _on_stop_signals(loop, stop.set)
    started()
    gc.collect()
    gc.freeze()  # the long-lived set-up objects leave the collector's generations
    try:
        return await run_realtime(fleet, duration_s=duration_s, on_batch=on_batch, stop=stop)
    finally:
        gc.unfreeze()
        for signum in handled:
            loop.remove_signal_handler(signum)


def _on_stop_signals(
    loop: asyncio.AbstractEventLoop, callback: Callable[[], None]
) -> list[signal.Signals]:
    """SIGINT and SIGTERM call ``callback`` (main thread only; elsewhere nothing is installed)."""
    handled: list[signal.Signals] = []
    for signum in (signal.SIGINT, signal.SIGTERM):
        try:
            loop.add_signal_handler(signum, callback)
        except (RuntimeError, ValueError, NotImplementedError):
            continue
        handled.append(signum)
    return handled


async def _all_connected(bridge: Bridge, timeout_s: float) -> None:
    """Start the clock once every link is up (telemetry from tick 0 reaches the broker)."""
    try:
        async with asyncio.timeout(timeout_s):
            for link in bridge.links:
                await link.connected.wait()
    except TimeoutError:
        down = sum(not link.connected.is_set() for link in bridge.links)
        raise BrokerError(f"{down} of {len(bridge.links)} robots not connected to "
                          f"{bridge.config.broker} within {timeout_s:g} s") from None


def _endpoints(fleet: Fleet, run: FleetRun) -> list[RobotEndpoint]:
    p = run.fleet.robot
    geometry = Geometry.of(p)
    return [RobotEndpoint(name, fleet.host_bus(i), geometry, run.fleet.integrator, p.counter_bits)
            for i, name in enumerate(fleet.names)]


def _report(
    run: FleetRun, fleet: Fleet, stats: DeadlineStats, bridge: Bridge | None,
    url: BrokerURL | None, embedded: bool,
) -> dict[str, Any]:
    per_robot = {}
    for i, name in enumerate(fleet.names):
        frames = fleet.frame_counts(i)
        entry: dict[str, Any] = {"seed": run.fleet.seed + i, "frames": frames,
                                 "frames_total": sum(frames.values())}
        if bridge is not None:
            entry["commands_accepted"] = bridge.robots[i].commands_sent
            entry["commands_rejected"] = bridge.robots[i].commands_rejected
        per_robot[name] = entry
    return {
        "robots": run.fleet.robots,
        "duration_s": run.duration_s,
        "period_s": stats.period_s,
        "deadline_miss_ratio": stats.deadline_miss_ratio,
        "ticks": stats.ticks,
        "late_ticks": stats.late_ticks,
        "skipped_releases": stats.skipped_releases,
        "max_lateness_ms": round(stats.max_lateness_s * 1e3, 3),
        "broker": str(url) if url is not None else None,
        "embedded_broker": embedded,
        "bridge": None if bridge is None else bridge.counters(),
        "per_robot": per_robot,
    }
