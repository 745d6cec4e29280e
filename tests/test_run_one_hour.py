"""One hour of fault-free ``random`` driving through ``odocan run``, for every integrator.

The whole chain: the firmware's fixed-point odometry, its pose frames on the bus, decoded by the
host, against the float64 reference on the same encoder counts. Every on-board pose sample of
the hour must be within one LSB of the pose signals: 0.1 mm in X and Y, 2*pi/65536 rad in
heading (the quantisation of the signals is half of that; the firmware's own drift over an hour
is below 10 um and 1e-7 rad). About 45 s of CPU per integrator (2 min 13 s for the three).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.sim.rig import INTEGRATORS

HOUR_S = 3600
LSB_POSITION_M = 1e-4
LSB_HEADING_RAD = 2 * math.pi / 65536


@pytest.mark.slow
@pytest.mark.parametrize("integrator", INTEGRATORS)
def test_one_hour_random_within_one_lsb(
    integrator: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    report_path = tmp_path / "hour.json"
    argv = [
        "run",
        "--scenario",
        "random",
        "--duration",
        str(HOUR_S),
        "--seed",
        "2024",
        "--integrator",
        integrator,
        "--report",
        str(report_path),
    ]
    code = main(argv)
    out, err = capsys.readouterr()
    assert (code, err) == (0, ""), out
    report = json.loads(report_path.read_text())
    assert report["integrator"] == integrator
    assert report["frames"]["WHEEL_ENCODERS"] == HOUR_S * 100
    assert report["onboard_vs_truth"]["distance_travelled_m"] > 500  # speeds up to 1 m/s
    errors = report["onboard_vs_reference"]
    assert errors["max_position_error_m"] <= LSB_POSITION_M
    assert errors["max_heading_error_rad"] <= LSB_HEADING_RAD
    assert all(
        counts["lost"] == 0 and counts["crc_errors"] == 0 for counts in report["e2e"].values()
    )
    assert report["passed"] is True
