"""UMBmark and the calibration (``odocan umbmark``, ``odocan calibrate``): Borenstein & Feng's
formulas against a hand-computed example, their signs checked by simulation, the firmware
corrected over CAN, and the issue's acceptance figures.

Acceptance (issue #5): with ``--errors ed=1.002,eb=1.01`` (seed 0) the calibration recovers E_d and
E_b within 10 % of their deviation from 1 (E_d within 1.002 +- 0.0002, E_b within 1.01 +- 0.001)
and E_max,syst falls at least 5x.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from odocan.host.cli import app as cli
from odocan.host.experiments import umbmark
from odocan.host.experiments.drive import ExperimentError, NavSession
from odocan.host.experiments.umbmark import CentreOfGravity, Correction
from odocan.host.judge.reference import Geometry
from odocan.sim.errors import ErrorModel
from odocan.sim.robot import load

PMIR = load("pmir")
OUR_COMMANDS = ("experiment", "umbmark", "calibrate")


def test_our_subcommands_are_registered() -> None:
    assert set(OUR_COMMANDS) <= set(cli.SUBCOMMANDS)


def run_cli(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, *argv: str
) -> tuple[str, dict[str, Any]]:
    """``odocan ARGV --report tmp`` must exit 0 with nothing on stderr; stdout and the report."""
    path = tmp_path / "report.json"
    code = cli.main([*argv, "--report", str(path)])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert err == "", err
    return out, json.loads(path.read_text())


# --- the formulas ---------------------------------------------------------------------------


def test_borenstein_against_a_hand_computed_example() -> None:
    """L = 4 m, b = 0.3 m, alpha = 0.01 rad, beta = 0.02 rad. First order (module docstring):
    x_cw = -2L(alpha + beta) = -0.24 m, x_ccw = 2L(beta - alpha) = 0.08 m. Back:
    alpha = (-0.24 + 0.08)/(-16) = 0.01, beta = (-0.24 - 0.08)/(-16) = 0.02,
    E_b = 1.5707963/(1.5707963 - 0.01) = 1.0064070, R = 2/sin(0.01) = 200.00333 m,
    b/2 = 0.15 * E_b = 0.1509610 m, E_d = 200.15430/199.85237 = 1.0015107."""
    cw, ccw = CentreOfGravity(-0.24, -0.25), CentreOfGravity(0.08, -0.07)
    est = umbmark.borenstein(cw, ccw, 4.0, 0.3)
    assert est.alpha_rad == pytest.approx(0.01, abs=1e-15)
    assert est.beta_rad == pytest.approx(0.02, abs=1e-15)
    assert est.eb == pytest.approx(1.0064070, abs=1e-7)
    assert est.radius_m == pytest.approx(200.00333, abs=1e-5)
    assert est.ed == pytest.approx(1.0015107, abs=1e-7)


def test_borenstein_without_curvature_and_the_centres_of_gravity() -> None:
    est = umbmark.borenstein(CentreOfGravity(-0.1, 0.0), CentreOfGravity(-0.1, 0.0), 4.0, 0.3)
    assert est.beta_rad == 0.0
    assert est.ed == 1.0
    assert math.isinf(est.radius_m)
    assert est.alpha_rad == pytest.approx(0.0125)
    cg = umbmark.centre_of_gravity([(0.3, -0.4), (0.1, 0.0), (0.2, -0.2)])
    assert (cg.x_m, cg.y_m) == pytest.approx((0.2, -0.2))
    assert cg.r_m == pytest.approx(0.2828427)


def test_the_correction_is_the_error_models_actual_geometry() -> None:
    """Borenstein's correction (mean radius kept) of (E_d, E_b) is exactly the robot that
    sim.errors builds with them: a perfect estimate makes the firmware's geometry the truth's."""
    model = ErrorModel(ed=1.002, eb=1.01)
    fixed = Correction.nominal(PMIR).corrected(model.ed, model.eb)
    left, right = model.actual_radii_m(PMIR)
    assert fixed.wheel_radius_left_m == pytest.approx(left, rel=1e-15)
    assert fixed.wheel_radius_right_m == pytest.approx(right, rel=1e-15)
    assert fixed.wheelbase_m == pytest.approx(model.actual_wheelbase_m(PMIR), rel=1e-15)


# --- the signs, by simulation ---------------------------------------------------------------


@pytest.mark.parametrize(
    ("errors", "signs"),
    [
        # E_d > 1: beta > 0 (left drift); CCW return error (+, -), CW (-, -)
        (ErrorModel(ed=1.004), {"ccw": (1, -1), "cw": (-1, -1)}),
        # E_b > 1: alpha > 0 (turns short); CCW (-, +), CW (-, -)
        (ErrorModel(eb=1.02), {"ccw": (-1, 1), "cw": (-1, -1)}),
    ],
    ids=["ed", "eb"],
)
def test_signs_of_the_convention_by_simulation(
    errors: ErrorModel, signs: dict[str, tuple[int, int]]
) -> None:
    result = umbmark.run_umbmark(PMIR, errors, 0, runs_per_direction=1)
    for direction, (sx, sy) in signs.items():
        cg = result.cg(direction)
        assert cg.x_m * sx > 0.05, (direction, cg)
        assert cg.y_m * sy > 0.05, (direction, cg)
    est = umbmark.borenstein(result.cg("cw"), result.cg("ccw"), 4.0, PMIR.wheelbase_m)
    assert est.ed - 1 == pytest.approx(errors.ed - 1, abs=0.15 * 0.004)
    assert est.eb - 1 == pytest.approx(errors.eb - 1, abs=0.15 * 0.02)
    assert (est.beta_rad > 0) == (errors.ed > 1)
    assert (est.alpha_rad > 0) == (errors.eb > 1)


# --- over CAN ---------------------------------------------------------------------------------


def test_configure_writes_the_geometry_over_can_and_a_nack_is_an_error() -> None:
    fixed = Correction.nominal(PMIR).corrected(1.002, 1.01)
    with NavSession(PMIR, ErrorModel(), 0) as session:
        session.configure(fixed.wheel_radius_left_m, fixed.wheel_radius_right_m, fixed.wheelbase_m)
        params = session.rig.board.ecu.params
        assert (params.wheel_radius_left_nm, params.wheel_radius_right_nm, params.wheelbase_nm) == (
            round(fixed.wheel_radius_left_m * 1e9), round(fixed.wheel_radius_right_m * 1e9),
            round(fixed.wheelbase_m * 1e9))
        with pytest.raises(ExperimentError, match="NACK"):
            session.configure(0.075, 0.075, 0.0)
        assert session.rig.board.ecu.params == params  # all or nothing


# --- the benchmark and the calibration ------------------------------------------------------


def test_umbmark_without_errors_has_a_tiny_emax(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    out, report = run_cli(capsys, tmp_path, "umbmark", "--errors", "")
    assert report["error_model"] == {"ed": 1.0, "eb": 1.0, "slip": 0.0}
    for direction in ("cw", "ccw"):
        runs = report[direction]["runs"]
        assert len(runs) == 5
        assert all({"x_m", "y_m"} <= r.keys() for r in runs)
        cg = report[direction]["cg"]
        assert cg["x_m"] == pytest.approx(sum(r["x_m"] for r in runs) / 5)
        assert report[direction]["r_cg_m"] == pytest.approx(math.hypot(cg["x_m"], cg["y_m"]))
    assert report["emax_syst_m"] == max(report["cw"]["r_cg_m"], report["ccw"]["r_cg_m"])
    assert report["emax_syst_m"] < 0.005
    assert "E_max,syst" in out
    assert "c.g." in out
    assert "r_c.g." in out


@pytest.mark.slow
def test_calibration_acceptance(capsys: pytest.CaptureFixture[str], tmp_path: Path) -> None:
    """Issue #5: E_d, E_b within 10 % of their deviation from 1, E_max,syst at least 5x lower."""
    out, report = run_cli(capsys, tmp_path, "calibrate", "--errors", "ed=1.002,eb=1.01")
    assert report["injected"] == {"ed": 1.002, "eb": 1.01, "slip": 0.0}
    estimated = report["estimated"]
    assert abs(estimated["ed"] - 1.002) <= 0.1 * 0.002
    assert abs(estimated["eb"] - 1.01) <= 0.1 * 0.01
    assert report["emax_before_m"] >= 5 * report["emax_after_m"]
    corrected = Correction.nominal(PMIR).corrected(estimated["ed"], estimated["eb"])
    assert report["corrected"] == {
        "wheel_radius_left_m": corrected.wheel_radius_left_m,
        "wheel_radius_right_m": corrected.wheel_radius_right_m,
        "wheelbase_m": corrected.wheelbase_m,
    }
    for phase in ("before", "after"):
        assert {"cw", "ccw", "emax_syst_m"} <= report[phase].keys()
        assert {"x_m", "y_m"} == report[phase]["cw"]["cg"].keys()
    assert report["before"]["emax_syst_m"] == report["emax_before_m"]
    assert "Before" in out
    assert "After" in out
    assert "ODOM_CONFIG" in out


@pytest.mark.parametrize(
    ("argv", "words"),
    [
        (["umbmark", "--errors", "ed=3"], ["ed=3.0", "outside"]),
        (["umbmark", "--errors", "eb"], ["key=value"]),
        (["umbmark", "--runs", "0"], ["--runs"]),
        (["umbmark", "--side", "-4"], ["--side"]),
        (["umbmark", "--seed", "-2"], ["--seed"]),
        (["umbmark", "--robot", "nosuch"], ["nosuch"]),
        (["umbmark", "--report", "/nonexistent/dir/r.json"], ["--report"]),
        (["calibrate", "--method", "guess"], ["--method", "guess"]),
        (["calibrate", "--errors", "slip=0.9"], ["slip=0.9", "outside"]),
        (["calibrate", "--side", "nan"], ["--side"]),
    ],
)
def test_bad_options_are_one_line_exit_2(
    capsys: pytest.CaptureFixture[str], argv: list[str], words: list[str]
) -> None:
    code = cli.main(argv)
    out, err = capsys.readouterr()
    assert code == 2, (code, out, err)
    assert out == "", (code, out, err)
    lines = err.splitlines()
    assert len(lines) == 1, err
    assert lines[0].startswith("error: "), err
    for word in words:
        assert word in lines[0], (word, lines[0])


# --- issue #11: the counter width, the verdicts --------------------------------------------------


@pytest.mark.parametrize("bits", [16, 32])
def test_dead_reckoning_wraps_at_the_counter_width(bits: int) -> None:
    """500 counts a frame on both wheels, from just below the wrap: the wire carries the low
    min(bits, 24) bits, so the deltas must wrap there (a 16-bit counter at 2^16, not 2^24)."""
    wire = 1 << min(bits, 24)
    counts = (np.arange(200, dtype=np.int64) * 500 + wire - 20_000) % wire
    geometry = Geometry.of(PMIR)
    end = umbmark.dead_reckoned_end((counts, counts), geometry, bits)
    assert end == pytest.approx([199 * 500 * geometry.m_per_count_left, 0.0], abs=1e-9)


def profile_file(tmp_path: Path, name: str, counts_per_rev: int, bits: int) -> str:
    path = tmp_path / f"{name}.toml"
    path.write_text(
        f'name = "{name}"\ncounts_per_rev = {counts_per_rev}\nwheel_radius_left_m = 0.05\n'
        f"wheel_radius_right_m = 0.0502\nwheelbase_m = 0.41\ncounter_bits = {bits}\n"
    )
    return str(path)


CALIBRATIONS = [  # robot, side (m): every shipped profile, past their 16-bit wraps, and custom
    ("kobuki", "4"),
    ("pmir", "16"),  # 64 m of wheel travel a square: past the 61.8 m wrap of its 16-bit counters
    ("custom16", "8"),
    ("custom32", "4"),  # 2^20 counts/rev: the 24 bits on the wire wrap every 5 m
]


@pytest.mark.slow
@pytest.mark.parametrize(("robot", "side"), CALIBRATIONS)
def test_calibration_recovers_the_errors_on_every_profile(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, robot: str, side: str
) -> None:
    """Issue #11: E_d, E_b within 10 % of their deviation from 1, E_max,syst at least 5x lower,
    PASS (one run each way: without slip every run is the same)."""
    if robot.startswith("custom"):
        bits = int(robot[-2:])
        robot = profile_file(tmp_path, robot, 4096 if bits == 16 else 1 << 20, bits)
    out, report = run_cli(capsys, tmp_path, "calibrate", "--robot", robot, "--side", side,
                          "--errors", "ed=1.002,eb=1.01", "--seed", "3", "--runs", "1")
    estimated = report["estimated"]
    assert abs(estimated["ed"] - 1.002) <= 0.1 * 0.002, estimated
    assert abs(estimated["eb"] - 1.01) <= 0.1 * 0.01, estimated
    assert report["emax_before_m"] >= 5 * report["emax_after_m"]
    assert report["passed"]
    assert report["faults"] == []
    assert out.endswith("calibrate: PASS\n")


@pytest.mark.slow
def test_calibration_of_implausible_errors_fails_with_a_reason(
    capsys: pytest.CaptureFixture[str], tmp_path: Path
) -> None:
    path = tmp_path / "report.json"
    code = cli.main(["calibrate", "--robot", "kobuki", "--errors", "ed=1.9,eb=1.9", "--seed", "3",
                     "--runs", "1", "--report", str(path)])
    out, err = capsys.readouterr()
    assert code == 1
    assert err == ""
    verdict = out[out.index("calibrate: FAIL\n"):].splitlines()
    assert len(verdict) >= 2
    assert all(line.startswith("  - ") for line in verdict[1:])
    assert "implausible estimate" in out
    report = json.loads(path.read_text())
    assert not report["passed"]
    assert report["faults"] == [line[4:] for line in verdict[1:]]


@pytest.fixture(scope="module")
def small_square() -> umbmark.UmbmarkResult:
    """One 1 m square each way on pmir with E_b = 1.01 (E_max,syst about 0.1 m)."""
    return umbmark.run_umbmark(PMIR, ErrorModel(eb=1.01), 0, side_m=1.0, runs_per_direction=1)


def test_a_valid_benchmark_has_no_faults_and_a_wrong_firmware_has(
    small_square: umbmark.UmbmarkResult,
) -> None:
    assert umbmark.faults(small_square, PMIR) == []
    # judged as if the firmware had kobuki's geometry: its on-board ends are not what that
    # firmware would have computed from the same counts
    wrong = umbmark.faults(small_square, load("kobuki"))
    assert len(wrong) == 2
    assert all("float64 reference" in r for r in wrong)
    assert wrong[0].startswith("CW run 1: ")
    assert wrong[1].startswith("CCW run 1: ")


def test_calibration_that_does_not_improve_fails(small_square: umbmark.UmbmarkResult) -> None:
    nominal = Correction.nominal(PMIR)
    cal = umbmark.Calibration(
        small_square, umbmark.borenstein(small_square.cg("cw"), small_square.cg("ccw"), 1.0, 0.3),
        (1.0, 1.0), "model", nominal, nominal, small_square,
    )
    assert umbmark.calibration_faults(cal, PMIR, 1.0) == []
    reasons = umbmark.calibration_faults(cal, PMIR, 2.0)
    assert len(reasons) == 1
    assert reasons[0].startswith("the correction does not cut E_max,syst 2x")
    far = umbmark.Calibration(
        small_square, cal.borenstein, (2.5, 1.0), "model", nominal, nominal, small_square,
        fit_residual_m=1.0,
    )
    reasons = umbmark.calibration_faults(far, PMIR, 1.0)
    assert reasons[0] == "implausible estimate E_d 2.5, E_b 1 (outside 0.5..2.0)"
    assert reasons[1].startswith("implausible estimate: the model fit leaves 1000.0 mm RMS")


@pytest.mark.parametrize(("limit", "code"), [("50", 0), ("40", 1)])
def test_umbmark_fails_beyond_max_emax(
    capsys: pytest.CaptureFixture[str], limit: str, code: int
) -> None:
    argv = ["umbmark", "--errors", "eb=1.01", "--side", "1", "--runs", "1", "--max-emax", limit]
    assert cli.main(argv) == code
    out = capsys.readouterr().out
    if code:
        assert out.endswith("UMBmark: FAIL\n  - E_max,syst 43.5 mm exceeds --max-emax 40 mm\n")
    else:
        assert out.endswith("UMBmark: PASS\n")
