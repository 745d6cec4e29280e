"""A bridge command sent while the bridge waits for the firmware's PROFILE page (no ``--robot``:
``host.judge.liverobot`` holds the frames up to 1.5 s) is judged by the judges that are kept.

Measured before the fix: the bridge followed its own ODOM_SET_POSE frames when sent, while the
frames before them were still held, so the APPLY was taken to follow encoder frame -1 (the judges
then replaced had heard none): ``cmd/result`` still said ``acked``, but the ``set_pose`` event
read "reference restarted at the next on-board pose" (the pose set never checked: a firmware
applying another pose was not told apart) and the APPLY's kept check was not made ("fewer than
two on-board poses before the APPLY"), where a bridge given ``--robot`` restarts the reference at
the pose set and makes the check. The expected values are the test's own: the frames decoded with
cantools and the float64 path of ``tests.test_live_set_pose``.
"""

from __future__ import annotations

import math
from typing import Any

import can

from odocan.firmware import frames as fr
from odocan.firmware.errors import ErrorMask
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.endverdict import end_verdict
from odocan.host.mqtt.livecommands import PendingAck
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim.board import TICK_S
from tests import host_frames as hf
from tests.fault_rig import open_virtual
from tests.test_health_rig import circle_rig
from tests.test_live_set_pose import DB, HEADING_RAW, X_RAW, Y_RAW, _independent

AT = 20  # the set-pose's first frame, tick 20 (0.2 s): before the first PROFILE page (0.5 s)
SET = {"X": (fr.SetPoseField.X, X_RAW), "Y": (fr.SetPoseField.Y, Y_RAW),
       "HEADING": (fr.SetPoseField.HEADING, HEADING_RAW), "APPLY": (fr.SetPoseField.APPLY, 0)}
STATUS_ID = DB.get_message_by_name("ODOM_STATUS").frame_id


def _drive(fields: tuple[str, ...]) -> tuple[list[can.Message], Any]:
    """pmir on the circle for 3 s, a host sending ``fields`` (one frame a tick) from ``AT``."""
    frames: list[can.Message] = []
    with circle_rig() as rig:
        rig.observers.append(lambda _k, heard: frames.extend(heard))
        tool = open_virtual(rig.channel)
        sends = {AT + i: SET[name] for i, name in enumerate(fields)}

        def host(k: int) -> None:
            if k in sends:
                data = hf.pack_odom_set_pose(k - AT, *sends[k], ErrorMask())
                tool.send(can.Message(arbitration_id=fr.ODOM_SET_POSE_ID, data=data,
                                      is_extended_id=False, timestamp=k * TICK_S))

        rig.before_board.append(host)
        try:
            rig.run(3.0)
        finally:
            tool.shutdown()
    return frames, rig.profile


def _bridged(frames: list[can.Message], profile: Any, from_page: bool
             ) -> tuple[RobotTelemetry, list[dict[str, Any]]]:
    """``frames`` fed to a bridge's telemetry (``from_page``: no ``--robot``); the set-pose
    frames are its own command (sent, awaited, not heard back, as the bridge's ``_send_frame``);
    the telemetry, its watch ended, and its ``cmd/result`` payloads."""
    telemetry = RobotTelemetry("r1", Geometry.of(profile), "exact",
                               counter_bits=profile.counter_bits, profile_name="pmir",
                               from_page=from_page)
    command = object()
    results: list[dict[str, Any]] = []
    for msg in frames:
        if msg.arbitration_id == fr.ODOM_SET_POSE_ID:
            s: Any = DB.decode_message(msg.arbitration_id, bytes(msg.data), decode_choices=False)
            ack = PendingAck("c1", "set_pose", int(s["FIELD"]) == 15, bytes(msg.data), command)
            telemetry.expect_ack(msg.arbitration_id, int(s["COUNTER"]), ack)
            telemetry.command_sent(msg.arbitration_id, bytes(msg.data))
            continue
        results += [payload for topic, payload in telemetry.feed(msg)
                    if topic.endswith("result")]
    results += [payload for topic, payload in telemetry.end_watch() if topic.endswith("result")]
    return telemetry, results


def _set_poses(telemetry: RobotTelemetry) -> list[dict[str, Any]]:
    return [e for e in telemetry.status()[1]["events"] if e["kind"] == "set_pose"]


def test_the_premise_the_set_pose_is_sent_and_acked_before_the_first_page() -> None:
    frames, _ = _drive(("APPLY",))
    first_page_s = min(m.timestamp for m in frames
                       if m.arbitration_id == STATUS_ID and m.data[1] >> 4 == 6)
    ack_id = DB.get_message_by_name("ODOM_ACK").frame_id
    acked_s = min(m.timestamp for m in frames if m.arbitration_id == ack_id)
    assert AT * TICK_S < acked_s < first_page_s


def test_a_set_pose_sent_in_the_wait_restarts_the_reference_at_the_pose_set() -> None:
    frames, profile = _drive(("X", "Y", "HEADING", "APPLY"))
    start, expected = _independent(frames, profile)
    telemetry, results = _bridged(frames, profile, from_page=True)
    assert telemetry.robot.as_dict()["source"] == "PROFILE page"  # the wait was taken
    assert [(r["id"], r["result"]) for r in results] == [("c1", "acked")]
    [event] = _set_poses(telemetry)
    assert event["encoder_frame"] == start, event  # not "at the next on-board pose"
    assert math.isclose(event["x_m"], X_RAW * 1e-4, abs_tol=1e-12)
    ref = telemetry.tracker.reference
    assert ref is not None
    assert ref.seq > start + 200
    x, y, h = expected[ref.seq - start]
    assert math.hypot(ref.x_m - x, ref.y_m - y) < 1e-9
    assert abs(ref.heading_rad - h) < 1e-9
    assert end_verdict(telemetry, profile_name="pmir").verdict == "PASS"


def test_a_bare_apply_sent_in_the_wait_is_checked_as_with_robot_given() -> None:
    frames, profile = _drive(("APPLY",))
    waited, results = _bridged(frames, profile, from_page=True)
    given, _ = _bridged(frames, profile, from_page=False)
    assert [(r["id"], r["result"]) for r in results] == [("c1", "acked")]
    [event] = _set_poses(waited)
    assert event.get("kept_not_judged") is None, event
    assert event["kept"]["fields_kept"] == ["X", "Y", "HEADING"]
    assert event["kept"]["passed"] is True
    assert event == _set_poses(given)[0]  # the same judgement as with --robot pmir
