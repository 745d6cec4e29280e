"""An overloaded fleet run in process, for the overload tests (``test_fleet_overload``,
``test_fleet_overload_stretches``): a fake ``RealTimeClock`` makes the fleet's loop
(``sim.fleet.run_realtime``) late as the test says, every robot's frames go to its bridge
telemetry and to candump lines, and the fleet's report is made as ``run_fleet`` makes it."""

from __future__ import annotations

import asyncio
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace
from typing import Any

import pytest

from odocan.host.judge.reference import Geometry
from odocan.host.mqtt import fleetjudge, fleetrun
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim import fleet as sim_fleet
from odocan.sim import robot
from odocan.sim.board import TICK_S
from odocan.sim.cboard import load_library
from odocan.sim.fleet import Batch, Fleet, FleetConfig, frame_fields
from odocan.sim.realtime import DeadlineStats
from tests.independent_checker import Robot, Verdict, check
from tests.requires import require_executables


class LateTicksClock:
    """A fake ``RealTimeClock`` for ``run_realtime``, which reads it twice a tick: before its
    sleep (answered far ahead: no sleep) and for the tick's lateness, ``late()`` whole periods
    (the loop skips that many releases; a subclass says how many, this one none)."""

    def __init__(self) -> None:
        self.reads = 0
        self.k = 0  # the release the loop is at

    def now_s(self) -> float:
        self.reads += 1
        if self.reads % 2:
            return 1e9
        late = self.late()
        now_s = (self.k + late) * TICK_S + 0.0003
        self.k += late + 1
        return now_s

    def late(self) -> int:
        """Whole periods the tick at release ``k`` runs late."""
        return 0


@dataclass
class Overloaded:
    """What an overloaded run left: the report's ``per_robot``, each robot's frames as candump
    lines, the bus time of its first halted tick, the fleet's halts and skipped releases."""

    per_robot: dict[str, Any]
    lines: list[list[str]]
    halted: list[float | None]
    halts: int
    skipped_releases: int


def run_overloaded(monkeypatch: pytest.MonkeyPatch, clock: Callable[[], Any], *, robots: int,
                   seed: int, duration_s: float, firmware: str = "python") -> Overloaded:
    """A kobuki fleet of ``robots`` run ``duration_s`` of bus time on the fake clock
    ``clock`` (a class with ``now_s``, built by ``run_realtime``)."""
    profile = robot.load("kobuki")
    config = FleetConfig(robots=robots, robot=profile, seed=seed, firmware=firmware)
    monkeypatch.setattr(sim_fleet, "RealTimeClock", clock)
    lines: list[list[str]] = [[] for _ in range(robots)]
    with Fleet(config) as fleet:
        telemetry = [RobotTelemetry(name, Geometry.of(profile), config.integrator,
                                    counter_bits=profile.counter_bits) for name in fleet.names]
        fleetjudge.watch_halts(fleet, telemetry)  # as run_fleet does

        def on_batch(batch: Batch) -> None:
            for i, frame in batch:
                telemetry[i].feed_frame(frame)
                t_s, can_id, data = frame_fields(frame)
                lines[i].append(f"({t_s:.6f}) vcan0 {can_id:03X}#{data.hex().upper()}")

        stats = asyncio.run(sim_fleet.run_realtime(fleet, duration_s=duration_s,
                                                   on_batch=on_batch))
        assert isinstance(stats, DeadlineStats)
        bridge = SimpleNamespace(
            frames_dropped=0, frames_failed=0, counters=dict,
            robots=[SimpleNamespace(commands_sent=0, commands_rejected=0, telemetry=t)
                    for t in telemetry])
        run = fleetrun.FleetRun(fleet=config, duration_s=duration_s)
        report = fleetrun._report(run, fleet, stats, bridge, None, False)  # type: ignore[arg-type]
        halted = [fleet.halted_from_s(i) for i in range(robots)]
        return Overloaded(dict(report["per_robot"]), lines, halted, fleet.halts,
                          stats.skipped_releases)


def checked_before(tmp_path: Path, lines: list[str], until_s: float) -> Verdict:
    """The independent checker (kobuki, from power-up) on the robot's frames before
    ``until_s``."""
    log = tmp_path / "before.log"
    log.write_text("\n".join(li for li in lines if float(li[1:li.index(")")]) < until_s) + "\n")
    p = robot.load("kobuki").firmware_params()
    kobuki = Robot(p["counts_per_rev"], p["wheel_radius_left_nm"], p["wheel_radius_right_nm"],
                   p["wheelbase_nm"], p["counter_bits"], p["max_wheel_speed_mm_s"])
    return check(log, kobuki, "exact", lambda t: (0.0, 0.0, 0.0))


FIRMWARES = ("python", "c")  # both (the fleet's default is the C port where it builds)


def ready(firmware: str) -> str:
    """``firmware``, its library built and loaded when it is the C port (else a skip)."""
    if firmware == "c":
        require_executables("make", "cc", install="apt-get install gcc make")
        load_library()
    return firmware
