"""A real-time fleet worker's cyclic GC (``fleetrun.TickCollector``): no automatic collection
while the clock runs, no young pass either unless the young generation passed its bound (a
leak's guard), the rest at the end, and the collector left as it was found."""

from __future__ import annotations

import asyncio
import gc
from typing import Any

import pytest

from odocan.host.mqtt import fleetrun
from odocan.host.mqtt.fleetrun import FleetRun
from odocan.sim import robot
from odocan.sim.fleet import FleetConfig


def _passes() -> tuple[list[int], dict[str, Any]]:
    """The generations collected while the automatic collector was off, and the report."""
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
    assert gc.isenabled()
    assert gc.get_freeze_count() == 0
    return [generation for generation, on in seen if not on], report


def test_the_worker_collects_nothing_while_the_clock_runs_and_everything_at_the_end() -> None:
    while_off, report = _passes()
    assert report["ticks"] > 0
    assert while_off == [2]  # the one full pass at the end


def test_a_young_generation_past_its_bound_is_collected_after_the_tick(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(fleetrun.TickCollector, "young_bound", -1)  # always past it
    while_off, report = _passes()
    assert while_off.count(0) == report["ticks"]
    assert [g for g in while_off if g > 0] == [2]
    assert while_off[-1] == 2


def test_every_ticks_brings_back_a_young_pass_every_n_ticks(
        monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(fleetrun.TickCollector, "every_ticks", 2)
    while_off, report = _passes()
    assert while_off.count(0) == report["ticks"] // 2
    assert while_off[-1] == 2
