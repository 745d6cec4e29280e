"""The fleet's per-robot verdict (``host.mqtt.fleetrun``) is the live judge's rule, ``analyze``'s
one LSB (``host.judge.livefit.pose_wrong``): robots driven in lockstep (``sim.fleet.Fleet``),
their frames fed to the bridge's telemetry as ``run_fleet`` offers them, the report made by
``fleetrun._report`` from the trackers as after a real run."""

from __future__ import annotations

from types import SimpleNamespace
from typing import Any

import pytest

from odocan.firmware import frames as fw_frames
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt import fleetrun
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim import robot
from odocan.sim.board import TICK_S
from odocan.sim.fleet import Fleet, FleetConfig
from odocan.sim.realtime import DeadlineStats

WRONG_100UM = 3  # the injected error: 0.3 mm of x, three LSB of ODOM_POSE_X


def _lockstep_report(robots: int, duration_s: float) -> dict[str, Any]:
    """Run ``robots`` pmir robots (random drives) for ``duration_s`` of bus time in lockstep, the
    bridge's telemetry fed every frame; the fleet report's ``per_robot``."""
    profile = robot.load("pmir")
    config = FleetConfig(robots=robots, robot=profile, seed=11)
    run = fleetrun.FleetRun(fleet=config, duration_s=duration_s)
    stats = DeadlineStats(TICK_S, TICK_S / 2)
    with Fleet(config) as fleet:
        telemetry = [RobotTelemetry(name, Geometry.of(profile), config.integrator,
                                    counter_bits=profile.counter_bits) for name in fleet.names]
        for k in range(round(duration_s / TICK_S)):
            fleet.step(k)
            for i, frame in fleet.take_batch():
                telemetry[i].feed_frame(frame)
        bridge = SimpleNamespace(
            frames_dropped=0, frames_failed=0, counters=dict,
            robots=[SimpleNamespace(commands_sent=0, commands_rejected=0, telemetry=t)
                    for t in telemetry])
        report = fleetrun._report(run, fleet, stats, bridge, None, False)  # type: ignore[arg-type]
    return dict(report["per_robot"])


def test_a_robot_whose_pose_is_0_3_mm_wrong_fails(monkeypatch: pytest.MonkeyPatch) -> None:
    """From 20 s on, the firmware sends x 0.3 mm off its own pose. The live judge's one LSB says
    it is wrong; the old fleet rule (2 LSB widened by the path times half a heading LSB) passed
    it."""
    real = fw_frames.pack_odom_pose_x
    sent = [0]

    def off(counter: int, enc: int, x_100um: int, heading_bam16: int, errors: Any) -> bytes:
        sent[0] += 1
        late = sent[0] > 1000  # one ODOM_POSE_X every 20 ms: from 20 s on
        return real(counter, enc, x_100um + (WRONG_100UM if late else 0), heading_bam16, errors)

    monkeypatch.setattr(fw_frames, "pack_odom_pose_x", off)
    per_robot = _lockstep_report(1, 30.0)
    wrong = per_robot["robot001"]
    assert wrong["pose_vs_reference"]["samples"] > 1000
    assert wrong["pose_vs_reference"]["max_dpos_m"] > 2.5e-4  # the error is there, seen
    assert wrong["verdict"] == "FAIL", wrong["reason"]
    assert "position vs reference" in wrong["reason"]


def test_a_correct_fleet_of_ten_passes_a_60_s_drive() -> None:
    per_robot = _lockstep_report(10, 60.0)
    assert len(per_robot) == 10
    for name, entry in per_robot.items():
        assert entry["pose_vs_reference"]["samples"] > 2900, name
        assert entry["verdict"] == "PASS", (name, entry["reason"])
