"""Two tools commanding one robot on ODOM_SET_POSE and NAV_GOAL (issue #11: "two sources on one
ID are reported"; the ODOM_CONFIG case is ``tests.test_two_config_senders``).

The bridge's ``cmd/set_pose`` (or ``cmd/nav_goal``) and another tool's (its own
``CommandEncoder``: its own E2E COUNTERs, from 0 too) reach the bus interleaved frame for frame,
the other tool's first or the bridge's first. The firmware's Profile 2 receiver takes the first
frame of each COUNTER and drops the second (E2E REPEATED, unanswered): it sets the pose of the
sender whose frames came first. Independent of the judges: the ODOM_ACKs decoded with cantools,
and float64 dead reckoning from each tool's pose says which one the firmware runs.

Found on main: nobody said "two senders" (monitor, bridge, analyze); the bridge answered its
command ``acked`` also when the firmware never took a frame of it; and with the bridge's frames
first, the bridge's own judge took the other tool's pose (the latest frame of a COUNTER) and
FAILed the correct firmware (POSE WRONG).
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.cli.app import main
from odocan.host.mqtt.bridge import _Robot
from odocan.host.protocol.commands import CommandEncoder
from tests.bridge_pair import bridged_robot, reckoned_from
from tests.test_bridge_foreign_config import PERIODS, _events, _wrongs
from tests.test_two_config_senders import MINE, _Interleaved, recorded_drive

APPLY = 15  # ODOM_SET_POSE FIELD / ODOM_ACK REQUEST_FIELD of APPLY (the DBC's VAL_)
OTHER_POSE = {"id": "script", "x_m": 0.5, "y_m": 0.25, "heading_rad": 1.0}
MINE_POSE = {"id": "p1", "x_m": 1.5, "y_m": -0.25, "heading_rad": 0.5}
OTHER_GOAL = {"id": "script", "x_m": 2.0, "y_m": 1.0, "heading_rad": 0.25}
MINE_GOAL = {"id": "g1", "x_m": -1.0, "y_m": 0.5, "heading_rad": -0.5}


def _frames(name: str, payload: dict[str, Any]) -> list[tuple[int, bytes]]:
    """``payload`` as the other tool puts it on the bus (its own E2E COUNTERs, from 0)."""
    command = CommandEncoder().encode(name, json.dumps(payload).encode())
    return [(f.can_id, f.data) for f in command.frames]


def _drive(name: str, mine: dict[str, Any], other: dict[str, Any], other_first: bool
           ) -> tuple[_Robot, _Interleaved]:
    with bridged_robot(f"test-two-{name}-{other_first}") as (bridge, listener):
        board = _Interleaved(bridge, listener, _frames(name, other), other_first)
        for _ in range(100):
            board.period()
        answer = bridge.on_command(name, json.dumps(mine).encode())
        assert answer[0][1]["result"] == "accepted", answer
        for _ in range(PERIODS - 100):
            board.period()
    return bridge, board


def _runs_pose(board: _Interleaved, taken: dict[str, Any], dropped: dict[str, Any]) -> None:
    """The firmware's last whole pose (cantools) is dead reckoned from ``taken``, set at its
    APPLY's ACK, and not from ``dropped``."""
    applied = [k for k, s in board.acks
               if s["REQUEST_ID"] == fr.ODOM_SET_POSE_ID and s["REQUEST_FIELD"] == APPLY]
    assert len(applied) == 1, board.acks
    named = max(k for k, xy in board.poses.items() if len(xy) == 2)
    assert named >= PERIODS - 3
    for pose, right in ((taken, True), (dropped, False)):
        x_m, y_m, _ = reckoned_from(pose["x_m"], pose["y_m"], pose["heading_rad"],
                                    named - applied[0] + 1)
        off_m = math.hypot(board.poses[named]["X"] - x_m, board.poses[named]["Y"] - y_m)
        assert (off_m < 1e-3) is right, (pose, off_m)


def _said(bridge: _Robot, board: _Interleaved, message: str) -> None:
    """The bridge's command ``contested``, never ``acked``; the monitor's and the bridge's
    ``two senders`` event names the message."""
    assert [r["result"] for r in board.results] == ["contested"], board.results
    assert board.results[0]["reason"].startswith(
        f"two senders on {message}: another tool's frame (COUNTER ")
    monitor = [e["detail"] for e in board.monitor.events if e["kind"] == "two senders"]
    assert len(monitor) == 1, board.monitor.events
    assert monitor[0].startswith(f"two senders on {message}: COUNTER 0 repeated with other")
    assert len(_events(bridge, "two senders")) == 1


@pytest.mark.parametrize("other_first", [True, False])
def test_two_set_pose_senders_are_told_and_the_correct_firmware_passes(other_first: bool) -> None:
    bridge, board = _drive("set_pose", MINE_POSE, OTHER_POSE, other_first)
    taken, dropped = (OTHER_POSE, MINE_POSE) if other_first else (MINE_POSE, OTHER_POSE)
    _runs_pose(board, taken, dropped)
    _said(bridge, board, "ODOM_SET_POSE")
    assert _wrongs(bridge, board) == (0, 0)  # neither judge FAILs the correct firmware


@pytest.mark.parametrize("other_first", [True, False])
def test_two_nav_goal_senders_are_told(other_first: bool) -> None:
    bridge, board = _drive("nav_goal", MINE_GOAL, OTHER_GOAL, other_first)
    goes = [s for _, s in board.acks if s["REQUEST_ID"] == fr.NAV_GOAL_ID]
    assert [(int(s["REQUEST_FIELD"]), int(s["RESULT"])) for s in goes] == [
        (0, 0), (1, 0), (2, 0), (15, 0)]  # one of each COUNTER's two frames taken
    _said(bridge, board, "NAV_GOAL")
    assert _wrongs(bridge, board) == (0, 0)


class _Echoed(_Interleaved):
    """A bus that loops the bridge's frames back to it (the fleet's observer hears its sends;
    SocketCAN's loopback to another socket), and no other tool."""

    def command_frame(self, msg: can.Message) -> None:
        super().command_frame(msg)
        self.to_bridge(msg.arbitration_id, bytes(msg.data))


@pytest.mark.parametrize(("name", "payload"), [
    ("set_pose", MINE_POSE), ("nav_goal", MINE_GOAL), ("config", MINE)])
def test_the_bridges_own_frames_heard_back_are_not_a_second_sender(
        name: str, payload: dict[str, Any]) -> None:
    """Its own frames come back: one sender still (found in a fleet: every command
    ``contested``, a ``two senders`` event for each)."""
    with bridged_robot(f"test-echo-{name}") as (bridge, listener):
        board = _Echoed(bridge, listener, [], other_first=False)
        for _ in range(100):
            board.period()
        assert bridge.on_command(name, json.dumps(payload).encode())[0][1]["result"] == \
            "accepted"
        for _ in range(PERIODS - 100):
            board.period()
    assert [r["result"] for r in board.results] == ["acked"], board.results
    assert _events(bridge, "two senders") == []
    assert _wrongs(bridge, board) == (0, 0)


# --- analyze: a recorded drive, two tools' commands interleaved on the bus ---
def _recorded(path: Path, name: str, first: dict[str, Any], second: dict[str, Any] | None
              ) -> None:
    """``recorded_drive``: ``first`` from one tool and (unless None) ``second`` from another
    whose frames each follow the first's (its COUNTERs from 0 too): the firmware drops them
    (REPEATED)."""
    recorded_drive(path, _frames(name, first), None if second is None else _frames(name, second),
                   2.0)


@pytest.mark.parametrize("stream", ["never", "always"])
@pytest.mark.parametrize(("name", "message", "first", "second"), [
    ("set_pose", "ODOM_SET_POSE", MINE_POSE, OTHER_POSE),
    ("nav_goal", "NAV_GOAL", MINE_GOAL, OTHER_GOAL),
])
def test_analyze_reports_two_command_senders_and_passes_the_correct_firmware(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], name: str, message: str,
    first: dict[str, Any], second: dict[str, Any], stream: str,
) -> None:
    for two_tools in (True, False):
        log, report = tmp_path / f"{two_tools}.log", tmp_path / f"{two_tools}.json"
        _recorded(log, name, first, second if two_tools else None)
        assert main(["analyze", str(log), "--robot", "kobuki", "--stream", stream,
                     "--report", str(report)]) == 0
        said = json.loads(report.read_text())
        senders = [e["detail"] for e in said["events"] if e["kind"] == "two senders"]
        if two_tools:
            assert len(senders) == 1, senders
            assert senders[0].startswith(f"two senders on {message}: COUNTER 0 repeated with "
                                         "other content: the firmware drops the second frame")
        else:
            assert senders == []
    capsys.readouterr()
