"""A burst of set_pose commands must not overflow the firmware's mailbox nor mis-match ACKs.

Found by the MQTT trial (issues #11/#13): 16 and more ``cmd/set_pose`` published at once, the
bridge sent every frame at once; the firmware's 32-frame receive mailbox overflowed
(MAILBOX_OVERFLOW, encoder frames lost) and, with more than 16 ODOM_SET_POSE frames in flight,
an ODOM_ACK (matched by CAN id and 4-bit COUNTER) answered the wrong command while others were
never answered. Here a real Python firmware answers the bridge's frames (all the frames the
bridge put on the bus during a period reach the mailbox before the next tick); which command
each ODOM_ACK answers is worked out here, independently, from the order the firmware drained
the frames in (it answers them in that order), with cantools decoding the DBC.
"""

from __future__ import annotations

import json
from typing import Any, cast

import can

from odocan.firmware import frames as fr
from odocan.host.judge.livesetpose import SetPoseFollower
from odocan.sim.contract import database
from tests.bridge_pair import Board, bridged_robot

BURST = 40
DB = database()


def _decoded(can_id: int, data: bytes) -> dict[str, Any]:
    """The frame's signals, raw multiplexers (cantools: independent of the bridge's code)."""
    return dict(cast(dict[str, Any], DB.decode_message(can_id, data, decode_choices=False)))


class _Board(Board):
    """``Board`` (the bridge's frames reach the mailbox before the period's encoder frame),
    noting which command each APPLY drained and each APPLY's ACK belongs to."""

    def __init__(self, bridge: Any, listener: can.BusABC) -> None:
        super().__init__(bridge, listener)
        self.drained_applies: list[int] = []  # the command (by its X) of each APPLY delivered
        self.acked_applies: list[int] = []  # ... of each APPLY the firmware ACKed, in order
        self._last_x = -1
        self.answers_at_apply_ack: list[tuple[int, list[Any]]] = []

    def command_frame(self, msg: can.Message) -> None:
        dropped_before = self.ecu.mailbox.overflows
        super().command_frame(msg)
        if msg.arbitration_id != fr.ODOM_SET_POSE_ID:
            return
        s = _decoded(msg.arbitration_id, bytes(msg.data))
        if self.ecu.mailbox.overflows != dropped_before:
            return  # dropped: never drained, never answered
        if s["FIELD"] == 0:
            self._last_x = round(s["X"] * 1000)
        elif s["FIELD"] == 15:
            self.drained_applies.append(self._last_x)

    def firmware_frame(self, can_id: int, data: bytes) -> None:
        if can_id == fr.ODOM_ACK_ID:
            s = _decoded(can_id, data)
            if s["REQUEST_ID"] == fr.ODOM_SET_POSE_ID and s["REQUEST_FIELD"] == 15:
                x_mm = self.drained_applies[len(self.acked_applies)]
                self.acked_applies.append(x_mm)
                self.answers_at_apply_ack.append((x_mm, self.to_bridge(can_id, data)))
                return
        self.to_bridge(can_id, data)


def test_a_burst_of_40_set_poses_is_paced_answered_once_each_and_never_judged_wrong() -> None:
    with bridged_robot("test-command-pacing") as (bridge, listener):
        board = _Board(bridge, listener)
        for _ in range(50):
            board.period()
        accepted = []
        for k in range(BURST):  # x = k + 1 metres: the X frame names its command
            payload = {"id": f"p{k}", "x_m": k + 1.0, "y_m": 0.5, "heading_rad": 0.25}
            accepted += bridge.on_command("set_pose", json.dumps(payload).encode())
        for _ in range(200):
            board.period()

    assert [p["result"] for _, p in accepted] == ["accepted"] * BURST
    assert board.ecu.mailbox.overflows == 0  # the firmware lost no frame
    finals = [(r["id"], r["result"]) for r in board.results]
    assert finals == [(f"p{k}", "acked") for k in range(BURST)]  # each once, in order
    # each APPLY's ACK answered the command whose APPLY the firmware drained (worked out here)
    assert [(x_mm, [r["id"] for r in got]) for x_mm, got in board.answers_at_apply_ack] == [
        ((k + 1) * 1000, [f"p{k}"]) for k in range(BURST)]
    wrongs = bridge.telemetry.tracker.wrongs.as_dict()
    assert wrongs["episodes"] == 0, wrongs


def test_a_command_the_firmware_never_answers_times_out_once() -> None:
    """No firmware on the bus: the first command's frames go out, its deadline passes, it is
    answered ``timeout`` once, and the window goes on to the next (never stuck)."""
    with bridged_robot("test-command-pacing-silent", command_ack_timeout_s=0.0,
                       command_window_frames=4) as (bridge, _):
        answers = []
        for k in range(3):
            payload = {"id": k, "x_m": 1.0, "y_m": 0.5, "heading_rad": 0.25}
            answers += bridge.on_command("set_pose", json.dumps(payload).encode())
        for _ in range(5):
            answers += bridge.paced([])
    results = [(p["id"], p["result"]) for _, p in answers]
    assert sorted(results) == [(k, r) for k in range(3) for r in ("accepted", "timeout")]
    assert all(p["reason"] for _, p in answers if p["result"] == "timeout")
    assert not bridge.pacer.busy
    assert bridge.telemetry.pending == {}


def test_two_applies_heard_before_their_acks_are_each_followed() -> None:
    """Paced, two set-poses are in flight at once: the second APPLY heard must not hide the
    first's ACK (the follower kept one APPLY: the reference stayed on the old pose)."""
    follower = SetPoseFollower()
    follower.on_frame(0, "X", 1.0, 10)
    follower.on_frame(1, "APPLY", None, 10)
    follower.on_frame(2, "X", 2.0, 11)
    follower.on_frame(3, "APPLY", None, 11)
    assert follower.on_ack(0, True) is None
    assert follower.on_ack(1, True) == (10, {"X": 1.0})
    assert follower.on_ack(2, True) is None
    assert follower.on_ack(3, True) == (11, {"X": 2.0})
