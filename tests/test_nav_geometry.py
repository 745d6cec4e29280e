"""The navigation works on any wheelbase: its limits are at the wheels, not at the centre.

Found from outside: a 2 m wheelbase robot (equal radii, no errors) failed UMBmark, "the firmware
stopped 26.9 mm from its goal", its heading overshooting by 0.38 rad after REACHED: OMEGA_MAX
(2 rad/s) is 2 m/s at its rims and the final-turn P law then asked 6 m/s^2 of braking against
the 1 m/s^2 ACCEL limit. A 1 cm wheelbase never reached its goal (the final turn asked 0.4 mm/s,
below MOTOR_CMD's 1 mm/s step) and exited 2. Checked here with float64 arithmetic of our own and
the closed-loop rig's on-board end pose, not with the firmware's helpers.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from odocan.firmware import nav
from odocan.firmware.errors import ErrorMask
from odocan.host.experiments import umbmark
from odocan.sim.errors import ErrorModel
from odocan.sim.robot import load

ACCEL_M_S2 = 1.0  # the firmware's documented rim acceleration limit
K_TURN_PER_S = 3.0  # the documented final-turn gain: omega = 3.0/s * e
HEADING_TOL_RAD = math.radians(0.5)
COUNTS_PER_REV = 500
WHEELBASES_M = (0.01, 0.1, 0.3, 1.0, 2.0)
RADII_M = ((0.075, 0.075), (0.075, 0.0755))  # equal, and unequal (the right one 0.7 % larger)


@pytest.mark.parametrize("wheelbase_m", WHEELBASES_M)
def test_the_turn_law_never_asks_more_braking_than_the_rim_limit(wheelbase_m: float) -> None:
    """Turning in place, rim speed u = omega b/2 and the P law's braking K u must stay within
    ACCEL, for every heading error (the wheel speeds as the firmware sends them)."""
    wheelbase_nm = round(wheelbase_m * 1e9)
    for error_rad in (0.01, 0.05, 0.1, 0.3, 1.0, 3.0):
        error_bam32 = round(error_rad / (2 * math.pi) * 2**32)
        omega = nav.turn_rate_mrad_s(error_bam32, nav.K_TURN_MILLI_PER_S, ErrorMask())
        left, right = nav.wheel_speeds_mm_s(0, omega, wheelbase_nm)
        rim_m_s = max(abs(left), abs(right)) * 1e-3
        assert K_TURN_PER_S * rim_m_s <= ACCEL_M_S2 + 1e-9, (wheelbase_m, error_rad, rim_m_s)


@pytest.mark.parametrize("wheelbase_m", WHEELBASES_M)
def test_a_turn_in_place_always_moves_the_wheels(wheelbase_m: float) -> None:
    """Just outside the heading tolerance the turn still commands at least one MOTOR_CMD step
    (1 mm/s) at the rims."""
    wheelbase_nm = round(wheelbase_m * 1e9)
    error_bam32 = round(1.01 * HEADING_TOL_RAD / (2 * math.pi) * 2**32)
    omega = nav.turn_rate_mrad_s(error_bam32, nav.K_TURN_MILLI_PER_S, ErrorMask())
    left, right = nav.wheel_speeds_mm_s(0, omega, wheelbase_nm)
    assert right >= 1, (wheelbase_m, right)
    assert left <= -1, (wheelbase_m, left)


def _profile(tmp_path: Path, wheelbase_m: float, radii_m: tuple[float, float]) -> Path:
    path = tmp_path / "robot.toml"
    path.write_text(
        f'name = "b{wheelbase_m:g}"\ncounts_per_rev = {COUNTS_PER_REV}\n'
        f"wheel_radius_left_m = {radii_m[0]}\nwheel_radius_right_m = {radii_m[1]}\n"
        f"wheelbase_m = {wheelbase_m}\ncounter_bits = 16\n"
    )
    return path


def _heading_tolerance_rad(wheelbase_m: float, radii_m: tuple[float, float]) -> float:
    """0.5 degree, or one encoder count's heading step when coarser (2 pi r / (N b))."""
    count_rad = 2 * math.pi * max(radii_m) / (COUNTS_PER_REV * wheelbase_m)
    return max(HEADING_TOL_RAD, count_rad)


@pytest.mark.parametrize("radii_m", RADII_M, ids=("equal", "unequal"))
@pytest.mark.parametrize("wheelbase_m", WHEELBASES_M)
def test_umbmark_passes_on_any_wheelbase_and_ends_on_its_heading(
    tmp_path: Path, wheelbase_m: float, radii_m: tuple[float, float]
) -> None:
    profile = load(_profile(tmp_path, wheelbase_m, radii_m))
    result = umbmark.run_umbmark(
        profile, ErrorModel(ed=1.0, eb=1.0, slip=0.0), 0, side_m=0.5, runs_per_direction=1
    )
    assert umbmark.faults(result, profile) == []
    tolerance_rad = _heading_tolerance_rad(wheelbase_m, radii_m) + 0.002  # + coasting to rest
    for direction in umbmark.DIRECTIONS:
        (run,) = result.of(direction)
        path = umbmark.square_path(0.5, direction)
        reached = [m for m in run.drive.marks if m.state == "REACHED"]
        assert [m.goal_id for m in reached] == [1, 2, 3, 4]
        # the true heading: no errors, so the odometry's but for what the encoders cannot see,
        # less than a count at each wheel (two counts' heading steps)
        count_rad = 2 * math.pi * max(radii_m) / (COUNTS_PER_REV * wheelbase_m)
        for mark in reached:
            want_rad = path[mark.goal_id - 1].heading_rad
            assert want_rad is not None
            off_rad = math.remainder(mark.pose.heading_rad - want_rad, 2 * math.pi)
            assert abs(off_rad) < tolerance_rad + 2 * count_rad, (direction, mark.goal_id, off_rad)
        goal = path[-1]
        assert goal.heading_rad is not None
        heading_rad = run.drive.onboard_end[2]
        off_rad = math.remainder(heading_rad - goal.heading_rad, 2 * math.pi)
        assert abs(off_rad) < tolerance_rad, (direction, heading_rad, goal.heading_rad)


def test_a_path_not_reached_is_a_failed_experiment_exit_1(
    monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """A firmware that does not reach its path is a failed experiment (exit 1, one line), not
    bad input (exit 2): here the square is given 2 s instead of its time."""
    from odocan.host.cli.app import main

    monkeypatch.setattr(umbmark, "square_timeout_s", lambda side_m, wheelbase_m=0.3: 2.0)
    code = main(["umbmark", "--runs", "1", "--side", "0.5"])
    _, err = capsys.readouterr()
    assert code == 1, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("FAIL: path of 4 goals not reached"), err


def test_a_correction_the_firmware_refuses_is_a_failed_calibration_exit_1(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """On a 1 cm wheelbase with the default errors, UMBmark's E_max is metres and Borenstein's
    E_b comes out near 0.7: a 0.7 cm wheelbase, below the firmware's 1 cm minimum, NACKed. The
    calibration failed (exit 1, one line naming the geometry), nothing typed was wrong."""
    from odocan.host.cli.app import main

    robot = _profile(tmp_path, 0.01, RADII_M[0])
    code = main(["calibrate", "--robot", str(robot), "--runs", "1", "--method", "borenstein"])
    _, err = capsys.readouterr()
    assert code == 1, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("FAIL: the firmware refused the corrected geometry"), err
    assert "NACK (OUT_OF_RANGE)" in lines[0], err
