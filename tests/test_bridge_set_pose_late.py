"""A set_pose whose APPLY the firmware takes one encoder frame after the one the bridge had heard.

Found in a harness (≈4 mm open POSE WRONG episode) and reproduced here: the bridge notes, when it
sends the APPLY, the latest encoder frame it has heard, and restarted its reference at the set
pose there. On a live bus its reader lags: the next encoder frame may already be on the bus
(ahead of the APPLY) but not yet heard, and the firmware then applies the pose after that frame,
so the reference was one step ahead of a correct firmware for good. Here a real Python firmware
takes the bridge's frames after the period's encoder frame (``Board.period(late=True)``); where
its pose must be is worked out independently (float64 exact arcs of the constant step from the
set pose, written here, from the frame the firmware applied it on).
"""

from __future__ import annotations

import json
from typing import Any

import pytest

from odocan.firmware.odometry import Odometry
from tests.bridge_pair import Board, bridged_robot, reckoned_from

SET = {"x_m": 1.0, "y_m": 0.5, "heading_rad": 0.25}


def _after_set_pose(steps: int) -> tuple[float, float, float]:
    """Independent float64: ``steps`` exact arcs of the constant step from the set pose."""
    return reckoned_from(SET["x_m"], SET["y_m"], SET["heading_rad"], steps)


def _drive(late: bool, channel: str) -> tuple[Board, dict[str, Any]]:
    with bridged_robot(channel) as (bridge, listener):
        board = Board(bridge, listener)
        for _ in range(50):
            board.period()
        bridge.on_command("set_pose", json.dumps({"id": "s", **SET}).encode())
        board.period(late=late)  # the firmware applies it after encoder frame 50 (late) or 49
        for _ in range(150):
            board.period()
    return board, bridge.telemetry.tracker.wrongs.as_dict()


def test_a_set_pose_applied_one_frame_after_the_bridge_heard_is_followed(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    for late, channel in ((True, "test-set-pose-late"), (False, "test-set-pose-on-time")):
        board, wrongs = _drive(late, channel)
        assert [(r["id"], r["result"]) for r in board.results] == [("s", "acked")]
        # frames 0..200: applied after frame 50 (late) or 49, then stepped to frame 200
        x_m, y_m, _ = _after_set_pose(150 if late else 151)
        pose = board.ecu.odometry  # the firmware is right ...
        assert abs(pose.x_q40_m / 2.0**40 - x_m) < 1e-4, late
        assert abs(pose.y_q40_m / 2.0**40 - y_m) < 1e-4, late
        assert wrongs["episodes"] == 0, (late, wrongs)  # ... and the judge says so

    # a firmware that sets the pose 2 mm off is judged wrong, whichever frame it took it after
    real = Odometry.set_pose

    def off(self: Odometry, x_q40_m: int, y_q40_m: int, heading: int) -> None:
        real(self, x_q40_m + 2 * (1 << 40) // 1000, y_q40_m, heading)

    monkeypatch.setattr(Odometry, "set_pose", off)
    for late, channel in ((True, "test-set-pose-late-off"), (False, "test-set-pose-on-time-off")):
        _, wrongs = _drive(late, channel)
        assert wrongs["episodes"] >= 1, (late, wrongs)
