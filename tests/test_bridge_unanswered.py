"""The bridge answers ``acked`` only when every staged frame of its command was answered
(issue #11's remainder: "the bridge answers `acked` at the APPLY's ACK even if one staged frame
of its command was never answered").

A ``cmd/config`` (kobuki, wheelbase 0.27 m) and a ``cmd/set_pose`` reach the firmware one
frame short: the bus loses their WHEELBASE / X frame (the firmware's E2E receiver takes the
next frame as OKSOMELOST). The firmware stages the rest and ACKs the APPLY: it commits a config
without the wheelbase asked for, a pose without the x asked for. Independent of the bridge: the
ODOM_ACKs decoded with cantools show that frame never answered.

Found on main: the bridge answered both ``acked``.
"""

from __future__ import annotations

import json
from typing import Any, cast

import can

from odocan.firmware import frames as fr
from odocan.host.mqtt.bridge import _Robot
from odocan.sim.contract import database
from tests.bridge_pair import KOBUKI, Board, bridged_robot

DB = database()
CONFIG = {"id": "c1", "counts_per_rev": KOBUKI.counts_per_rev,
          "wheel_radius_left_m": KOBUKI.wheel_radius_left_m,
          "wheel_radius_right_m": KOBUKI.wheel_radius_right_m, "wheelbase_m": 0.27,
          "counter_bits": 16, "integrator": "exact"}
POSE = {"id": "p1", "x_m": 1.5, "y_m": -0.25, "heading_rad": 0.5}


class _Lossy(Board):
    """``Board`` whose bus loses the bridge's frames of one multiplexer value (``lost``: CAN ID,
    its PARAM or FIELD); keeps the firmware's ODOM_ACKs."""

    def __init__(self, bridge: _Robot, listener: can.BusABC, lost: tuple[int, int]) -> None:
        super().__init__(bridge, listener)
        self.lost = lost
        self.acks: list[dict[str, Any]] = []

    def command_frame(self, msg: can.Message) -> None:
        mux = DB.decode_message(msg.arbitration_id, bytes(msg.data), decode_choices=False)
        field = cast(dict[str, Any], mux).get("PARAM", cast(dict[str, Any], mux).get("FIELD"))
        if (msg.arbitration_id, field) == self.lost:
            self.commands.append(msg)  # sent, never delivered
            return
        super().command_frame(msg)

    def firmware_frame(self, can_id: int, data: bytes) -> None:
        if can_id == fr.ODOM_ACK_ID:
            self.acks.append(cast(dict[str, Any],
                                  DB.decode_message(can_id, data, decode_choices=False)))
        super().firmware_frame(can_id, data)


def _drive(channel: str, name: str, payload: dict[str, Any], lost: tuple[int, int]
           ) -> _Lossy:
    with bridged_robot(channel) as (bridge, listener):
        board = _Lossy(bridge, listener, lost)
        for _ in range(50):
            board.period()
        answer = bridge.on_command(name, json.dumps(payload).encode())
        assert answer[0][1]["result"] == "accepted", answer
        for _ in range(100):
            board.period()
    return board


def _answered_fields(board: _Lossy, request_id: int) -> list[tuple[int, int]]:
    """cantools: (REQUEST_FIELD, RESULT) of each ODOM_ACK of ``request_id``."""
    return [(int(a["REQUEST_FIELD"]), int(a["RESULT"])) for a in board.acks
            if a["REQUEST_ID"] == request_id]


def test_a_config_whose_wheelbase_frame_went_unanswered_is_not_acked() -> None:
    board = _drive("test-unanswered-config", "config", CONFIG, (fr.ODOM_CONFIG_ID, 3))
    assert _answered_fields(board, fr.ODOM_CONFIG_ID) == [(0, 0), (1, 0), (2, 0), (4, 0),
                                                          (5, 0), (15, 0)]  # no WHEELBASE
    assert [r["result"] for r in board.results] == ["unanswered"], board.results
    reason = board.results[0]["reason"]
    assert reason.startswith("ODOM_ACK ACK for its APPLY, but its ODOM_CONFIG WHEELBASE "
                             "(COUNTER 3) was never answered"), reason
    assert board.bridge.pacer.counters()["command_frames_in_flight"] == 0


def test_a_set_pose_whose_x_frame_went_unanswered_is_not_acked() -> None:
    board = _drive("test-unanswered-pose", "set_pose", POSE, (fr.ODOM_SET_POSE_ID, 0))
    assert _answered_fields(board, fr.ODOM_SET_POSE_ID) == [(1, 0), (2, 0), (15, 0)]  # no X
    assert [r["result"] for r in board.results] == ["unanswered"], board.results
    assert board.results[0]["reason"].startswith(
        "ODOM_ACK ACK for its APPLY, but its ODOM_SET_POSE X (COUNTER 0) was never answered")


def test_a_whole_config_is_acked() -> None:
    board = _drive("test-unanswered-none", "config", CONFIG, (0, 0))
    assert _answered_fields(board, fr.ODOM_CONFIG_ID) == [(f, 0) for f in (0, 1, 2, 3, 4, 5, 15)]
    assert [r["result"] for r in board.results] == ["acked"], board.results
