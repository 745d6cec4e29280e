"""host.protocol.session: one command session for every host that drives a firmware, checked on
the closed-loop lockstep rig (our firmware answering on a python-can bus), and the encoder's
values path (``CommandEncoder.build``) against its JSON path (``encode``)."""

from __future__ import annotations

import json
import math
import uuid
from collections.abc import Iterator
from typing import Any

import pytest

from odocan.host.protocol.commands import CommandEncoder, CommandRejected
from odocan.host.protocol.heard import Recorder, UnknownMessageError
from odocan.host.protocol.session import CommandNotAcked, CommandSession
from odocan.sim.contract import database
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load

PMIR = load("pmir")


@pytest.fixture
def rig_and_session() -> Iterator[tuple[LockstepRig, CommandSession]]:
    """Our firmware in closed loop, booted (0.2 s), and a session on its host handle."""
    heard = Recorder(database())
    config = RigConfig(robot=PMIR, scenario=None, channel=f"odocan-session-{uuid.uuid4().hex}")
    rig = LockstepRig(config, [heard])
    rig.run(0.2)
    yield rig, CommandSession(heard, rig.send, rig.run_until, ack_timeout_s=0.5)
    rig.close()


def test_set_pose_is_acked_by_the_committing_frame_and_applied(
    rig_and_session: tuple[LockstepRig, CommandSession],
) -> None:
    rig, session = rig_and_session
    ack = session.set_pose(1.25, -0.5, 0.25)
    assert ack["RESULT"] == "ACK"
    assert ack["REQUEST_ID"] == "ODOM_SET_POSE"
    rig.run(0.05)
    pose = session.heard.latest_pose()
    assert pose is not None
    assert pose.x_m == pytest.approx(1.25, abs=1e-4)
    assert pose.y_m == pytest.approx(-0.5, abs=1e-4)
    assert pose.heading_rad == pytest.approx(0.25, abs=2 * math.pi / 65536)


def test_a_nack_names_the_firmwares_reason_and_the_values(
    rig_and_session: tuple[LockstepRig, CommandSession],
) -> None:
    rig, session = rig_and_session
    params = rig.board.ecu.params
    with pytest.raises(CommandNotAcked, match=r"config \{.*'wheelbase_m': 0.02.*\}: NACK") as err:
        session.configure(counts_per_rev=1, wheel_radius_left_m=0.075, wheel_radius_right_m=0.075,
                          wheelbase_m=0.02, counter_bits=16, integrator="exact")
    assert err.value.reason.startswith("NACK ")
    assert rig.board.ecu.params == params  # all or nothing


def test_no_answer_within_the_timeout_is_not_acked() -> None:
    heard = Recorder(database())
    sent: list[tuple[int, bytes]] = []
    waited: list[float] = []

    def wait(done: Any, timeout_s: float) -> bool:
        waited.append(timeout_s)
        return bool(done())

    session = CommandSession(heard, lambda i, d: sent.append((i, d)), wait, ack_timeout_s=0.7)
    with pytest.raises(CommandNotAcked, match="no ODOM_ACK") as err:
        session.set_pose(0.0, 0.0, 0.0)
    assert err.value.reason == "no ODOM_ACK"
    assert len(sent) == 4  # X, Y, HEADING, APPLY
    assert waited == [0.7]


def test_an_invalid_command_is_rejected_before_anything_is_sent() -> None:
    sent: list[tuple[int, bytes]] = []
    session = CommandSession(Recorder(database()), lambda i, d: sent.append((i, d)),
                             lambda done, t: True, ack_timeout_s=0.5)
    with pytest.raises(CommandRejected, match="x_m must be finite"):
        session.set_pose(math.nan, 0.0, 0.0)
    assert sent == []


@pytest.mark.parametrize("heading_rad", [1e300, -3e11])
def test_a_heading_too_large_to_wrap_is_rejected(heading_rad: float) -> None:
    """1e300 rad was accepted and ACKed (found by the trial): float64's ulp there is ~1e284 rad,
    so its wrap to [0, 2 pi) is an arbitrary heading. The limit: half HEADING's LSB of ulp."""
    sent: list[tuple[int, bytes]] = []
    session = CommandSession(Recorder(database()), lambda i, d: sent.append((i, d)),
                             lambda done, t: True, ack_timeout_s=0.5)
    with pytest.raises(CommandRejected, match=r"heading_rad=.* too large to wrap"):
        session.set_pose(0.0, 0.0, heading_rad)
    assert sent == []
    lsb_rad = 2 * math.pi / 65536
    ulp_at_limit_rad = math.ulp(lsb_rad * 2.0**51)
    assert ulp_at_limit_rad <= lsb_rad / 2  # the largest accepted heading still wraps exactly


def test_a_goal_is_followed_from_its_ack_to_reached(
    rig_and_session: tuple[LockstepRig, CommandSession],
) -> None:
    rig, session = rig_and_session
    ack = session.goal(0.3, 0.0, goal_id=7)
    assert session.goal_acked_at[7] == ack["timestamp_s"]
    assert rig.run_until(lambda: session.goal_ended(7), 30.0)
    states = [f["STATE"] for f in session.goal_states(7)]
    assert states[-1] == "REACHED"
    assert all(f["timestamp_s"] >= ack["timestamp_s"] for f in session.goal_states(7))
    changes = session.status_changes()
    assert [(c.goal_id, c.state) for c in changes][-1] == (7, "REACHED")
    assert len({(c.goal_id, c.state) for c in changes}) == len(changes)  # changes, not repeats
    assert session.status_changes() == []  # each change is handed out once


def test_build_makes_the_frames_encode_makes_of_the_same_json() -> None:
    values = {"x_m": 1.5, "y_m": -0.25, "mode": "go_to_goal", "append": True, "goal_id": 9}
    by_values = CommandEncoder().build("nav_goal", values)
    by_json = CommandEncoder().encode("nav_goal", json.dumps(values).encode())
    assert by_values.frames == by_json.frames
    assert by_values.values == values
    assert len(by_values.frames) == 3  # X, Y, GO (no HEADING without heading_rad)


def test_heard_decodes_from_a_start_and_names_an_unknown_message(
    rig_and_session: tuple[LockstepRig, CommandSession],
) -> None:
    _, session = rig_and_session
    all_status = session.heard.decoded("NAV_STATUS")
    assert len(all_status) >= 2
    assert session.heard.decoded("NAV_STATUS", 1) == all_status[1:]
    with pytest.raises(UnknownMessageError, match="no message 'NOPE'"):
        session.heard.decoded("NOPE")
