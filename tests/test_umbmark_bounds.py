"""Issue #11 point 2: UMBmark on robots where Borenstein's small-angle model breaks (a 1 cm
wheelbase, a 16 m square) must not PASS with a wrong estimate, and a correction the firmware
refuses must be named (parameter, value, the firmware's range).

The independent check is written here in float64 from the report's raw end positions: the
centres of gravity, E_max,syst / L and Borenstein & Feng's first-order E_b, E_d (their paper's
equations in the start frame of the ``umbmark`` module docstring), not the product's code."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any

import pytest

from odocan.host.cli import app as cli

BOUND = 0.25  # the stated small-angle bound, E_max,syst / L (umbmark_bounds.SMALL_ANGLE_BOUND)


def robot_file(tmp_path: Path, wheelbase_m: float, bits: int) -> str:
    path = tmp_path / f"b{wheelbase_m:g}_{bits}.toml"
    path.write_text(
        f'name = "b{bits}"\ncounts_per_rev = 2578\nwheel_radius_left_m = 0.035\n'
        f"wheel_radius_right_m = 0.035\nwheelbase_m = {wheelbase_m}\ncounter_bits = {bits}\n"
        "max_wheel_speed_m_s = 0.7\n"
    )
    return str(path)


def main(tmp_path: Path, capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str]:
    """Exit code and stdout; a verdict has nothing on stderr."""
    code, out, err = main_err(tmp_path, capsys, *argv)
    assert err == "", err
    return code, out


def main_err(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], *argv: str
) -> tuple[int, str, str]:
    code = cli.main([*argv, "--report", str(tmp_path / "report.json")])
    out, err = capsys.readouterr()
    return code, out, err


def independent(report: dict[str, Any], wheelbase_m: float) -> tuple[float, float, float]:
    """(E_max,syst / L, E_d, E_b) from the runs' true and on-board ends, float64."""
    side_m = report["side_m"]
    cg = {}
    for direction in ("cw", "ccw"):
        runs = report[direction]["runs"]
        ex = [r["true_end_x_m"] - r["onboard_end_x_m"] for r in runs]
        ey = [r["true_end_y_m"] - r["onboard_end_y_m"] for r in runs]
        cg[direction] = (sum(ex) / len(ex), sum(ey) / len(ey))
    emax_m = max(math.hypot(*cg[d]) for d in cg)
    alpha = (cg["cw"][0] + cg["ccw"][0]) / (-4 * side_m)
    beta = (cg["cw"][0] - cg["ccw"][0]) / (-4 * side_m)
    eb = (math.pi / 2) / (math.pi / 2 - alpha)
    radius_m = (side_m / 2) / math.sin(beta / 2)
    half_b = eb * wheelbase_m / 2
    return emax_m / side_m, (radius_m + half_b) / (radius_m - half_b), eb


@pytest.mark.parametrize(
    ("wheelbase_m", "bits", "side", "errors", "passes"),
    [
        (0.01, 32, "4", "ed=1.01,eb=1.02", False),  # the user trial: return errors of 4.7 m
        (0.01, 16, "4", "ed=1.002,eb=1.01", False),
        (0.01, 32, "0.2", "ed=1.002,eb=1.01", True),  # a square scaled to the robot
        (2.0, 32, "4", "ed=1.002,eb=1.01", True),
        (0.23, 16, "4", "ed=1.002,eb=1.01", True),  # kobuki's geometry
    ],
)
def test_umbmark_fails_beyond_the_small_angle_model(
    capsys: pytest.CaptureFixture[str], tmp_path: Path,
    wheelbase_m: float, bits: int, side: str, errors: str, passes: bool,
) -> None:
    """Beyond the bound, Borenstein's first-order E_b (computed here) is more than 10 % of the
    injected deviation off: UMBmark exits 1 naming the model and a smaller side; within it, PASS."""
    robot = robot_file(tmp_path, wheelbase_m, bits)
    code, out = main(tmp_path, capsys, "umbmark", "--robot", robot,
                     "--side", side, "--errors", errors, "--runs", "1")
    report = json.loads((tmp_path / "report.json").read_text())
    ratio, _, eb = independent(report, wheelbase_m)
    injected_eb = float(errors.split("eb=")[1])
    assert (ratio <= BOUND) == passes, ratio
    if passes:
        assert code == 0, out
        assert report["faults"] == []
        return
    assert abs(eb - injected_eb) > 0.1 * (injected_eb - 1), eb  # the model does fail there
    assert code == 1
    assert "UMBmark: FAIL" in out
    assert any("small-angle model" in f and "--side" in f for f in report["faults"])


@pytest.mark.slow
def test_calibrate_borenstein_beyond_the_small_angle_model_fails(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """pmir on a 16 m square: Borenstein's E_b reads 0.998 for 1.01 (the wrong side of 1) and the
    correction still cut E_max,syst 4.6x, so this was a PASS with a wrong estimate."""
    code, _ = main(tmp_path, capsys, "calibrate", "--robot", "pmir", "--side", "16",
                     "--method", "borenstein", "--errors", "ed=1.002,eb=1.01", "--seed", "3",
                     "--runs", "1")
    report = json.loads((tmp_path / "report.json").read_text())
    ratio, _, eb = independent(report["before"], 0.41)
    assert ratio > BOUND
    assert abs(eb - 1.01) > 0.1 * 0.01, eb
    assert abs(report["estimated"]["eb"] - 1.01) > 0.1 * 0.01
    assert code == 1
    assert not report["passed"]
    assert any("small-angle model" in f for f in report["faults"]), report["faults"]


def test_a_refused_correction_is_named(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A 1 cm wheelbase on a 4 m square: the fit's E_b makes a wheelbase below the firmware's 10 mm
    minimum; the verdict names the parameter, its value and the range, not only the NACK."""
    robot = robot_file(tmp_path, 0.01, 32)
    code, _, err = main_err(tmp_path, capsys, "calibrate", "--robot", robot, "--errors",
                            "ed=1.01,eb=1.02", "--runs", "1")
    assert code == 1
    assert "Traceback" not in err
    eb = float(re.search(r"E_b ([0-9.]+)", err)[1])  # type: ignore[index]
    wheelbase_mm = 10.0 * eb
    assert wheelbase_mm < 10.0
    range_mm = r"the firmware's range 10 \.\. 4000 mm"
    named = re.search(r"wheelbase ([0-9.]+) mm is outside " + range_mm, err)
    assert named is not None, err
    assert "small-angle model" in err  # why the estimate is wrong, and the way out
    assert float(named[1]) == pytest.approx(wheelbase_mm, rel=1e-5)


def test_a_square_scaled_to_a_1cm_robot_calibrates_it(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """Control (passes before the bound too): the way out the verdict names works. On a 0.4 m
    square the 1 cm robot's E_d 1.01, E_b 1.02 come back within 10 % of their deviation and
    E_max,syst (computed here from the raw ends) falls at least 5x: PASS."""
    robot = robot_file(tmp_path, 0.01, 32)
    code, out = main(tmp_path, capsys, "calibrate", "--robot", robot, "--side", "0.4",
                     "--errors", "ed=1.01,eb=1.02", "--runs", "1")
    report = json.loads((tmp_path / "report.json").read_text())
    before, _, _ = independent(report["before"], 0.01)
    after, _, _ = independent(report["after"], 0.01)
    assert abs(report["estimated"]["ed"] - 1.01) <= 0.1 * 0.01
    assert abs(report["estimated"]["eb"] - 1.02) <= 0.1 * 0.02
    assert before >= 5 * after
    assert code == 0, out


def test_a_failed_model_fit_beyond_the_bound_names_the_small_angle_model(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    """A 3 cm wheelbase on the 4 m square (E_max,syst 3.6 L): the model fit, started from
    Borenstein's estimate, lands on E_b 0.45 for 1.02 and fails on its residual; the verdict also
    says why (the small-angle model) and the way out (a smaller --side)."""
    robot = robot_file(tmp_path, 0.03, 32)
    code, _ = main(tmp_path, capsys, "calibrate", "--robot", robot, "--errors", "ed=1.01,eb=1.02",
                   "--runs", "1")
    report = json.loads((tmp_path / "report.json").read_text())
    ratio, _, _ = independent(report["before"], 0.03)
    assert ratio > BOUND
    assert abs(report["estimated"]["eb"] - 1.02) > 0.1 * 0.02
    assert code == 1
    assert any("small-angle model" in f and "--side" in f for f in report["faults"])
