"""The one pose pairing: X and Y halves naming the same encoder frame, never the latest of each."""

from __future__ import annotations

import math
from collections.abc import Mapping

from odocan.host.protocol.pose import Pose, PosePairer, latest_pose, pose_of


def x_half(counter: int, x_m: float, heading_rad: float) -> dict[str, float]:
    return {"ENC_COUNTER": counter, "X": x_m, "HEADING": heading_rad}


def y_half(counter: int, y_m: float, turns: int) -> dict[str, float]:
    return {"ENC_COUNTER": counter, "Y": y_m, "TURNS": turns}


def test_the_heading_is_unwrapped_by_turns() -> None:
    pose = pose_of(x_half(3, 1.5, 0.25), y_half(3, -2.0, -2))
    assert pose.x_m == 1.5
    assert pose.y_m == -2.0
    assert pose.heading_rad == -2 * 2.0 * math.pi + 0.25


def test_a_lost_y_half_never_pairs_two_ticks() -> None:
    pairer = PosePairer()
    pairer.on_x(x_half(1, 1.0, 0.1))
    # the Y of encoder frame 1 is lost; the next tick names frame 2
    pairer.on_x(x_half(2, 2.0, 0.2))
    assert pairer.on_y(y_half(2, 20.0, 0)) == Pose(2.0, 20.0, 0.2)
    # a late Y of frame 1 still finds its own X, not the newer one
    assert pairer.on_y(y_half(1, 10.0, 0)) == Pose(1.0, 10.0, 0.1)
    # and an X is used once
    assert pairer.on_y(y_half(2, 20.0, 0)) is None


def test_a_y_without_its_x_gives_nothing() -> None:
    assert PosePairer().on_y(y_half(5, 1.0, 0)) is None


def test_latest_pose_of_a_stream_with_a_lost_x() -> None:
    stream: list[tuple[str, Mapping[str, float]]] = [
        ("ODOM_POSE_X", x_half(7, 7.0, 0.7)),
        ("ODOM_POSE_Y", y_half(7, 70.0, 1)),
        ("WHEEL_ENCODERS", {"COUNTER": 9}),
        ("ODOM_POSE_Y", y_half(8, 80.0, 1)),  # its X was lost
    ]
    assert latest_pose(stream) == Pose(7.0, 70.0, 2 * math.pi + 0.7)
    assert latest_pose([]) is None


def test_halves_naming_different_encoder_frames_are_not_paired() -> None:
    """The Y of frame 17 (ENC_COUNTER 1) whose X was lost must not complete the X of frame 1."""
    pairer = PosePairer()
    pairer.on_x(x_half(1, 1.0, 0.1), frame_seq=1)
    assert pairer.on_y(y_half(1, 170.0, 0), frame_seq=17) is None
    pairer.on_x(x_half(1, 17.0, 1.7), frame_seq=17)
    assert pairer.on_y(y_half(1, 170.0, 0), frame_seq=17) == Pose(17.0, 170.0, 1.7)
