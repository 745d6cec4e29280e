"""Two tools commanding one robot on ODOM_CONFIG (issue #11: "two sources on one ID are
reported").

Another tool (a script with its own ``CommandEncoder``: its own E2E COUNTERs from 0) and the
bridge's ``cmd/config`` put their ODOM_CONFIG frames on the bus interleaved, the other tool's
first: both start at COUNTER 0, so every bridge frame repeats the COUNTER the firmware has just
accepted. The Profile 2 receiver drops such a frame (E2E REPEATED) and answers nothing: the
firmware applies the other tool's config (wheelbase 0.25 m) and never sees the bridge's
(0.27 m). Independent of the judges: the ODOM_ACKs decoded with cantools, and the float64 dead
reckoning of ``tests.test_bridge_config_nack`` says where the pose must be.

Found on main: the bridge answered its config ``acked`` (the other tool's ODOM_ACKs carry the
same REQUEST_COUNTERs); the monitor took the bridge's frames (the latest of each COUNTER) as the
staged set and judged the correct firmware with 0.27 m: POSE WRONG; nobody said "two senders".
"""

from __future__ import annotations

import json
from typing import Any

import can

from odocan.firmware import frames as fr
from odocan.host.mqtt.bridge import _Robot
from tests.bridge_pair import bridged_robot
from tests.test_bridge_foreign_config import (
    PERIODS,
    WIDER,
    _assert_pose,
    _config_frames,
    _events,
    _Watched,
    _wrongs,
)

OTHER = {**WIDER, "id": "script"}  # wheelbase 0.25 m: the other tool's
MINE = {**WIDER, "id": "c1", "wheelbase_m": 0.27}  # the bridge's


class _Interleaved(_Watched):
    """Each frame the bridge sends reaches the bus right after one of the other tool's."""

    def __init__(self, bridge: _Robot, listener: Any, other: list[tuple[int, bytes]]) -> None:
        super().__init__(bridge, listener)
        self.other = list(other)

    def command_frame(self, msg: can.Message) -> None:
        if self.other:
            self.other_tool([self.other.pop(0)])
        super().command_frame(msg)


def _interleaved_drive(channel: str) -> tuple[_Robot, _Interleaved]:
    with bridged_robot(channel) as (bridge, listener):
        board = _Interleaved(bridge, listener, _config_frames(OTHER))
        for _ in range(100):
            board.period()
        answer = bridge.on_command("config", json.dumps(MINE).encode())
        assert answer[0][1]["result"] == "accepted", answer
        for _ in range(PERIODS - 100):
            board.period()
    return bridge, board


def test_two_senders_interleaved_on_odom_config() -> None:
    bridge, board = _interleaved_drive("test-two-config-senders")
    config_acks = [s for _, s in board.acks if s["REQUEST_ID"] == fr.ODOM_CONFIG_ID]
    assert [s["RESULT"] for s in config_acks] == [0] * 7  # cantools: the other tool's 7 only
    _assert_pose(board, 0, board.apply_periods[0])  # float64: 0.25 m from its APPLY on
    # the bridge never reports its config applied: the firmware never took one frame of it
    assert [r["result"] for r in board.results if r["id"] == "c1"] == ["contested"], board.results
    assert board.results[-1]["reason"].startswith("two senders on ODOM_CONFIG: another tool")
    # the judges follow what the firmware took: a correct firmware is not FAILed
    assert bridge.telemetry.tracker.geometry.wheelbase_m == 0.25
    assert board.monitor.tracker.geometry.wheelbase_m == 0.25
    assert _wrongs(bridge, board) == (0, 0)
    # and both say why: two senders on ODOM_CONFIG, an event with its reason
    monitor_events = [e["detail"] for e in board.monitor.events if e["kind"] == "two senders"]
    assert monitor_events, board.monitor.events
    assert monitor_events[0].startswith("two senders on ODOM_CONFIG: COUNTER 0 repeated")
    assert any("ODOM_CONFIG" in d for d in _events(bridge, "two senders"))
