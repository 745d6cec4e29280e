"""Two firmwares on one node ID, live (issue #11): the bridge and the fleet's end verdict name
them as the monitor and ``analyze`` do, and blame no pose after the second's first summary
(the log of ``tests.test_two_sources_verdict``: firmware A drives it, B powered up at 3 s on
the same bus until 6 s, both correct; the independent checker shows A right up to B there).

Found before: the monitor forgot the episodes from the conflict on
(``PoseWrongs.unjudgeable_from``), the bridge never did: its FAIL line named the two firmwares
and "the on-board pose was wrong in 1 episode (280 samples), worst 1158.6 mm"; the fleet's
(``watched_verdict``, which reads the largest errors and the allowance's maximum, never
withdrawn) said only "heading vs reference 103.7 mrad; position vs reference 1161 mm". A pose
wrong before the second firmware still FAILs for it.
"""

from __future__ import annotations

from pathlib import Path

import can

from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.endverdict import end_verdict
from odocan.host.mqtt.fleetjudge import watched_verdict
from odocan.host.mqtt.telemetry import RobotTelemetry
from tests.test_two_sources_verdict import PMIR, first_summary_of_b, two_firmwares


def _live(path: Path) -> tuple[BusMonitor, RobotTelemetry]:
    monitor = BusMonitor(PMIR, "exact")
    bridge = RobotTelemetry("r1", Geometry.of(PMIR), "exact", counter_bits=PMIR.counter_bits)
    for msg in can.LogReader(str(path)):
        monitor.feed(msg, now_s=msg.timestamp)
        bridge.feed(msg)
    return monitor, bridge


def test_the_bridge_and_the_fleet_name_the_two_firmwares_only(tmp_path: Path) -> None:
    path = two_firmwares(tmp_path)
    named = (f"two firmwares answered on one node ID from t={first_summary_of_b(path):.3f} s: "
             "the pose cannot be judged")
    monitor, bridge = _live(path)
    assert monitor.tracker.wrongs.count == 0
    assert bridge.tracker.wrongs.count == 0
    verdict = end_verdict(bridge)
    assert (verdict.verdict, verdict.reason) == ("FAIL", named)
    fleet = watched_verdict(bridge, 0, None)
    assert (fleet["verdict"], fleet["reason"]) == ("FAIL", named)


def test_a_pose_wrong_before_the_second_firmware_still_fails_for_it(tmp_path: Path) -> None:
    path = two_firmwares(tmp_path, bias={100: 30})  # A 3 mm off at 1 s
    monitor, bridge = _live(path)
    assert monitor.tracker.wrongs.count >= 1
    assert bridge.tracker.wrongs.count >= 1
    for reason in (end_verdict(bridge).reason, watched_verdict(bridge, 0, None)["reason"]):
        assert reason.startswith("two firmwares answered on one node ID from t=")
        assert "the on-board pose was wrong in 1 episode" in reason
