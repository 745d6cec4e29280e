"""A real-time fleet worker's cyclic GC (``fleetrun.TickCollector``): no automatic collection
while the clock runs, the young generation collected after every tick, the rest at the end, and
the collector left as it was found."""

from __future__ import annotations

import asyncio
import gc
from typing import Any

from odocan.host.mqtt import fleetrun
from odocan.host.mqtt.fleetrun import FleetRun
from odocan.sim import robot
from odocan.sim.fleet import FleetConfig


def test_the_worker_collects_the_young_generation_after_each_tick_and_the_rest_at_the_end(
) -> None:
    seen: list[tuple[int, bool]] = []  # (generation, automatic collector on) of each pass

    def on_gc(phase: str, info: dict[str, Any]) -> None:
        if phase == "start":
            seen.append((info["generation"], gc.isenabled()))

    run = FleetRun(fleet=FleetConfig(robots=2, robot=robot.load("pmir"), seed=3),
                   duration_s=0.3, bridge=False)
    assert gc.isenabled()
    gc.callbacks.append(on_gc)
    try:
        report = asyncio.run(fleetrun.run_fleet(run))
    finally:
        gc.callbacks.remove(on_gc)
    while_off = [generation for generation, on in seen if not on]
    assert report["ticks"] > 0
    # one young pass per tick the clock released, then the one full pass at the end
    assert while_off.count(0) == report["ticks"]
    assert [g for g in while_off if g > 0] == [2]
    assert while_off[-1] == 2
    assert gc.isenabled()
    assert gc.get_freeze_count() == 0
