"""The fleet's release gate and its workers' phases (``sim.releasegate``, issue #13): no bridge work
starts just before a tick, and the workers of one machine tick a fraction of a period apart."""

from __future__ import annotations

import asyncio
import time
from typing import Any

import pytest

from odocan.host.mqtt import shards
from odocan.host.mqtt.fleetrun import FleetRun
from odocan.sim import fleet as sim_fleet
from odocan.sim import robot
from odocan.sim.fleet import Fleet, FleetConfig, run_realtime
from odocan.sim.releasegate import AFTER_RELEASE_S, ReleaseGate, phased_start_s

PERIOD_S = 0.010


class FakeClock:
    def __init__(self, now_s: float) -> None:
        self.now_s = now_s

    def __call__(self) -> float:
        return self.now_s


@pytest.mark.parametrize(("left_s", "expected_s"), [
    (0.0050, 0.0),  # far from the release: work goes on
    (0.0016, 0.0),  # just beyond the margin: still room
    (0.0010, 0.0010 + AFTER_RELEASE_S),  # too close: until just after it
    (0.0, AFTER_RELEASE_S),  # due now: its tick goes first
    (-0.0030, 0.0),  # past: the loop runs behind, the tick is late anyway; no hold
])
def test_hold_until_just_after_a_near_release(left_s: float, expected_s: float) -> None:
    clock = FakeClock(100.0)
    gate = ReleaseGate(margin_s=0.0015, clock=clock)
    assert gate.hold_s() == 0.0  # no clock yet: nothing to wait for
    gate.next_s = 100.0 + left_s
    assert gate.hold_s() == pytest.approx(expected_s, abs=1e-12)


def test_clear_returns_after_the_release_and_counts_the_hold() -> None:
    gate = ReleaseGate(margin_s=0.0015)

    async def held() -> tuple[float, float]:
        gate.next_s = time.monotonic() + 0.001
        await gate.clear()
        after_s = time.monotonic()
        gate.next_s = after_s + 1.0  # far: no wait
        await gate.clear()
        return gate.next_s - 1.0, after_s

    release_s, woke_s = asyncio.run(held())
    assert woke_s >= release_s
    assert gate.holds == 1


@pytest.mark.parametrize(("left_s", "overrun"), [
    (0.0010, False),  # ahead: ``hold_s``'s case
    (-0.0005, True),  # just overrun, its tick not run yet: the tick first
    (-0.0049, True),
    (-0.0051, False),  # more than half a period past: late anyway, no wait (not starved)
])
def test_an_overrun_release_is_waited_for_until_its_tick(left_s: float, overrun: bool) -> None:
    clock = FakeClock(100.0)
    gate = ReleaseGate(margin_s=0.0015, clock=clock, overrun_s=0.005)
    assert not gate.overrun()  # no clock yet
    gate.next_s = 100.0 + left_s
    assert gate.overrun() is overrun
    gate.next_s = 100.0 + 0.0095  # the tick ran: the clock told the next release
    assert not gate.overrun()


def test_work_after_an_overrun_release_resumes_only_once_its_tick_ran() -> None:
    """Two waiting tasks (the bridge's slices and its periodic turn) resume after the clock
    tells the next release, not before; each wait is counted."""
    clock = FakeClock(100.0)
    gate = ReleaseGate(margin_s=0.0015, clock=clock, overrun_s=5.0)  # no timeout in this test
    order: list[str] = []

    async def work(name: str) -> None:
        await gate.clear()
        order.append(name)

    async def main() -> None:
        gate.next_s = 100.0 - 0.0004  # a slice overran the release by 0.4 ms
        waiting = [asyncio.create_task(work("slice")), asyncio.create_task(work("periodic"))]
        for _ in range(5):
            await asyncio.sleep(0)  # the loop turns; the tick has not run yet
        order.append("tick")
        gate.next_s = 100.0 + 0.0096  # the tick ran, the next release told
        await asyncio.gather(*waiting)

    asyncio.run(main())
    assert order == ["tick", "slice", "periodic"]
    assert (gate.holds, gate.overruns) == (2, 2)


def test_an_overrun_wait_ends_without_a_tick() -> None:
    """A clock that stopped (the run's end) tells no release: the wait ends after ``overrun_s``
    instead of holding the bridge for good."""
    gate = ReleaseGate(overrun_s=0.01)

    async def main() -> None:
        gate.next_s = time.monotonic() - 0.001
        await asyncio.wait_for(gate.clear(), timeout=5.0)

    asyncio.run(main())
    assert gate.overruns == 1


@pytest.mark.parametrize("fraction", [0.0, 0.25, 0.5, 0.75])
@pytest.mark.parametrize("now_s", [5.0, 5.0037, 5.0099, 123.4567891])
def test_phased_start_lies_on_its_fraction_within_a_period(fraction: float, now_s: float) -> None:
    epoch_s = 4.9983
    start_s = phased_start_s(epoch_s, fraction, PERIOD_S, now_s)
    assert now_s <= start_s < now_s + PERIOD_S
    periods = (start_s - epoch_s) / PERIOD_S - fraction
    assert periods == pytest.approx(round(periods), abs=1e-6)


def test_two_workers_start_half_a_period_apart() -> None:
    epoch_s = 50.0
    first = phased_start_s(epoch_s, 0.0, PERIOD_S, 50.3141)
    second = phased_start_s(epoch_s, 0.5, PERIOD_S, 50.3178)
    assert (second - first) % PERIOD_S == pytest.approx(PERIOD_S / 2, abs=1e-9)


class EarlyClock:
    """``run_realtime``'s clock read 3 ms before each release, then at it (never late: no
    release skipped however loaded the machine)."""

    def __init__(self) -> None:
        self.reads = 0

    def now_s(self) -> float:
        self.reads += 1
        k, after_sleep = divmod(self.reads - 1, 2)
        return k * PERIOD_S - (0.0 if after_sleep else 0.003)


def test_run_realtime_tells_the_gate_each_release(monkeypatch: pytest.MonkeyPatch) -> None:
    """Before waiting for release k, the gate is told it on the monotonic clock (3 ms ahead, as
    the clock says), and the tick never runs before it: work the gate holds runs after it."""
    monkeypatch.setattr(sim_fleet, "RealTimeClock", EarlyClock)
    gate = ReleaseGate()
    seen: list[tuple[float, float]] = []
    told: list[float] = []
    real_sleep = asyncio.sleep

    async def sleep(delay_s: float) -> None:  # the release as the gate was told it, on waiting
        told.append((gate.next_s or 0.0) - time.monotonic())
        await real_sleep(delay_s)

    async def main(fleet: Fleet) -> None:
        await run_realtime(fleet, duration_s=0.05, gate=gate,
                           on_batch=lambda _: seen.append((gate.next_s or 0.0,
                                                           time.monotonic())))

    monkeypatch.setattr(asyncio, "sleep", sleep)
    with Fleet(FleetConfig(robots=1, robot=robot.load("pmir"))) as fleet:
        asyncio.run(main(fleet))
    assert len(seen) == 5
    assert told == pytest.approx([0.003] * 5, abs=2e-4)
    for release_s, stepped_s in seen:
        assert stepped_s >= release_s - 1e-6  # no tick before the release the gate was told


def test_sharded_workers_get_their_phases(monkeypatch: pytest.MonkeyPatch) -> None:
    """``run_sharded`` gives worker ``w`` of ``n`` the phase ``w / n`` after one epoch."""
    runs_seen: list[FleetRun] = []

    def fake_workers(runs: list[FleetRun], *args: Any) -> list[dict[str, Any]]:
        runs_seen.extend(runs)
        raise RuntimeError("stop here")

    monkeypatch.setattr(shards, "_run_workers", fake_workers)
    run = FleetRun(fleet=FleetConfig(robots=6, robot=robot.load("pmir")), duration_s=1.0,
                   bridge=False)
    with pytest.raises(RuntimeError, match="stop here"):
        shards.run_sharded(run, 3)
    phases = [r.clock_phase for r in runs_seen]
    assert None not in phases
    epochs = {p[0] for p in phases if p is not None}
    assert len(epochs) == 1  # one epoch for the machine's workers
    assert [p[1] for p in phases if p is not None] == pytest.approx([0.0, 1 / 3, 2 / 3])
