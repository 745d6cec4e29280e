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

from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.endverdict import end_verdict
from odocan.host.mqtt.fleetjudge import watched_verdict
from odocan.host.mqtt.telemetry import RobotTelemetry
from tests.synth_log import synthesize, wandering_drive
from tests.test_two_sources_verdict import (
    DB,
    KILLED_AT,
    PMIR,
    SECOND_AT,
    STEPS,
    _frames,
    _later,
    first_summary_of_b,
    two_firmwares,
)

TWIST_ID = DB.get_message_by_name("ODOM_TWIST").frame_id


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


def _twisting(tmp_path: Path, wrong_from: int | None = None) -> Path:
    """The two firmwares' log with ODOM_TWIST (``synth_log``'s), A's twists lost while B answers
    (B's, DISTANCE from its own power-up, are the ones heard then); ``wrong_from``: A's DISTANCE
    10 mm long from that encoder frame (a wrong firmware before B)."""
    d_left, d_right = wandering_drive(PMIR, STEPS, 0.004, seed=7)
    wrong = None if wrong_from is None else (
        lambda k, mm, _odo: mm + 10 if k >= wrong_from else mm)
    a = synthesize(PMIR, "exact", d_left, d_right, twist=True, distance_of=wrong)
    b = synthesize(PMIR, "exact", d_left, d_right, reboot_at=SECOND_AT, twist=True)
    lines = a.lines(0, SECOND_AT) + a.lines(KILLED_AT)
    lines += [line for line in a.lines(SECOND_AT, KILLED_AT) if not line.split()[2].startswith(
        f"{TWIST_ID:03X}#")]
    lines += [_later(line) for line in _frames(b, SECOND_AT, KILLED_AT, firmware=True)]
    lines.sort(key=lambda line: float(line.split()[0].strip("()")))
    path = tmp_path / "two_twisting.log"
    path.write_text("".join(lines))
    return path


def test_distance_and_twist_are_withdrawn_from_the_second_firmware_on(tmp_path: Path) -> None:
    """B's twists heard in A's watch are not judged (its DISTANCE counts from its own power-up):
    the monitor and the bridge say the two firmwares only, as ``analyze`` does. Before, both
    added "ODOM_TWIST DISTANCE off the reference's path length by 1146.513 mm", blaming a
    correct firmware (live: 7536 mm in 1 of 3 runs)."""
    path = _twisting(tmp_path)
    t_b = first_summary_of_b(path)
    named = f"two firmwares answered on one node ID from t={t_b:.3f} s: the pose cannot be judged"
    monitor, bridge = _live(path)
    assert bridge.distance.samples > 150  # the premise: B's twists heard after A's
    for judge in (monitor, bridge):
        assert judge.distance.verdict() == []
        assert judge.twist.verdict() == []
    verdict = end_verdict(bridge)
    assert (verdict.verdict, verdict.reason) == ("FAIL", named)
    report = analyze(read_log(path), PMIR).report
    assert report["two_sources"]["detail"] == named
    assert report["onboard_distance_vs_reference"]["passed"]


def test_a_distance_wrong_before_the_second_firmware_still_fails_for_it(tmp_path: Path) -> None:
    path = _twisting(tmp_path, wrong_from=100)  # A's DISTANCE 10 mm long from 1 s
    monitor, bridge = _live(path)
    for judge in (monitor, bridge):
        assert judge.distance.verdict(), "a DISTANCE wrong before B is still wrong"
        assert 0.005 < judge.distance.worst_excess_m < 0.02  # A's 10 mm, not B's metres
    reason = end_verdict(bridge).reason
    assert reason.startswith("two firmwares answered on one node ID from t=")
    assert "ODOM_TWIST DISTANCE off the reference's path length by" in reason
