"""A clean drive pays nothing for the live judges' holds (issue #13 CPU; ``host.judge.livesettle``,
``host.mqtt.livehold``): a hold's context, the frames judged before it, is kept only from the
first frame heard off its period (``E2EMonitor.off_time``: a frame held is one). Before, the
bridge noted every frame of every robot in it (one tuple and one append a frame, ~1 % of a
robot-tick) and the monitor every frame too, though a clean drive never holds. The starved
captures' holds judge as before (tests/test_live_settle.py, tests/test_capture_bunched.py);
here the bridge's context is the monitor's, frame for frame (refused and held ones amended).
"""

from __future__ import annotations

from pathlib import Path

import can
import pytest

from odocan.host.cli.app import main
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim.robot import load
from tests.test_capture_bunched import _starved


def _drive(tmp_path: Path, faults: str | None) -> Path:
    log = tmp_path / "drive.log"
    main(["run", "--robot", "kobuki", "--duration", "2", "--seed", "3", "--log", str(log),
          "--firmware", "python", *(["--faults", faults] if faults else [])])
    return log


def _fed(capture: Path) -> tuple[BusMonitor, RobotTelemetry]:
    """The monitor model and the bridge's telemetry fed ``capture`` at its stamps."""
    profile = load("kobuki")
    monitor = BusMonitor(profile)
    bridge = RobotTelemetry("r", Geometry.of(profile), "exact", counter_bits=profile.counter_bits)
    with can.LogReader(str(capture)) as reader:
        for msg in reader:
            monitor.feed(msg, now_s=msg.timestamp)
            bridge.feed(msg)
    return monitor, bridge


def test_a_clean_drive_keeps_no_hold_context(tmp_path: Path) -> None:
    """No frame off its period: no context kept, the bridge's plans bare; judged OK. Before:
    both noted every frame (768 kept at the end)."""
    monitor, bridge = _fed(_drive(tmp_path, None))
    assert monitor.e2e.counts()["WHEEL_ENCODERS"]["ok"] > 150  # the drive was heard
    assert monitor.settle.recent is None
    assert bridge.hold.recent is None
    assert all(plan.__name__ != "kept_plan" for plan in bridge.plans.values())
    assert monitor.settle.holds == bridge.hold.settle.holds == 0
    assert monitor.health(now_s=0.0)["state"] == "OK"


@pytest.mark.parametrize("recorder", [1, 4])
def test_a_starved_capture_keeps_the_monitors_context_in_the_bridge(
        tmp_path: Path, recorder: int) -> None:
    """A starved recorder's capture (``delay=0.1:15``): both keep a context from the frame off
    its period on, the same frames with the same verdicts, and hold."""
    capture = tmp_path / "capture.log"
    _starved(_drive(tmp_path, "delay=0.1:15,seed=7"), capture, recorder)
    monitor, bridge = _fed(capture)
    assert monitor.settle.recent is not None
    assert bridge.hold.recent is not None
    assert monitor.settle.holds == bridge.hold.settle.holds > 0
    noted = [(msg.timestamp, msg.arbitration_id, bytes(msg.data), taken)
             for msg, taken in monitor.settle.recent]
    assert list(bridge.hold.recent) == noted
    assert any(not taken for *_, taken in noted)  # refused frames noted so
