"""A path the firmware's navigation cannot finish says where it stands.

Found in a user trial: ``odocan umbmark`` / ``calibrate`` / ``experiment`` on a robot with a 1 cm
wheelbase ended ``error: path of 4 goals not reached within 73.3333 s`` and nothing else. The
firmware's final turn there asks for wheel speeds below MOTOR_CMD's 1 mm/s step, so the robot
never turns the last mrad; the line now names the goal, its state and what is left of it.

Since branch ``nav`` (limits at the wheels for any wheelbase) that robot finishes its square, and
a path not reached is a failed experiment (exit 1, one ``FAIL:`` line), not bad input (exit 2).
The test keeps its purpose, the line that says where the path stands, on a path that really
cannot be reached: the same 1 cm robot given 3 s for its square.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.experiments import umbmark
from tests.test_cli_run import run_cli

TINY = """name = "tiny"
counts_per_rev = 1000
wheel_radius_left_m = 0.02
wheel_radius_right_m = 0.02
wheelbase_m = 0.01
counter_bits = 16
"""


def test_a_path_not_reached_names_the_goal_and_what_is_left(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], monkeypatch: pytest.MonkeyPatch
) -> None:
    """The square is given 3 s (not its time), so the firmware is still on a goal when the
    time is up: exit 1 and one line naming the goal, its state and what is left of it."""
    monkeypatch.setattr(umbmark, "square_timeout_s", lambda side_m, wheelbase_m=0.3: 3.0)
    robot = tmp_path / "tiny.toml"
    robot.write_text(TINY)
    code, _, err = run_cli(capsys, "umbmark", "--robot", str(robot), "--runs", "1")
    assert code == 1, err
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("FAIL: path of 4 goals not reached within 3 s"), err
    assert "goal 1 of 4 still " in lines[0], err
    assert "mrad from it by the firmware's own odometry" in lines[0], err
    assert "on-board pose x " in lines[0], err
