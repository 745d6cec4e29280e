"""A FAIL on ODOM_TWIST's speeds says by how much, never "by up to 0.000 m/s, 0.000 rad/s".

Found by the user trial (eleventh pass): a kobuki drive whose LINEAR_VEL was raised by one LSB
(1 mm/s) from 10 s on, re-signed with cantools' Profile 2 CRC, made `odocan analyze` print

    FAIL: on-board vs reference within 0.1 mm and 0.09587 mrad; ODOM_TWIST outside the
    reference's speeds by up to 0.000 m/s, 0.000 rad/s

(the report's excess was 0.18 mm/s: three decimals of m/s round it away), while the monitor says
the same excess in mm/s. The verdict now gives the excesses in mm/s and mrad/s to three
significant digits, as the report has them.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

from odocan.host.cli.app import main
from tests.log_edit import raise_raw

FROM_S = 10.0


def _raise_linear_vel(src: Path, dst: Path) -> int:
    """Copy ``src`` with ODOM_TWIST.LINEAR_VEL one LSB higher from ``FROM_S`` on (CRC re-signed,
    cantools); the number of frames changed."""
    return raise_raw(src, dst, "ODOM_TWIST", (2, 2), 1, FROM_S)  # LINEAR_VEL: 16|16


def test_a_twist_fail_names_a_nonzero_excess(tmp_path: Path,
                                             capsys: pytest.CaptureFixture[str]) -> None:
    log, edited, report = tmp_path / "r.log", tmp_path / "e.log", tmp_path / "e.json"
    assert main(["run", "--robot", "kobuki", "--duration", "20", "--log", str(log)]) == 0
    assert _raise_linear_vel(log, edited) > 400  # every twist of the last 10 s, 1 mm/s high
    capsys.readouterr()
    assert main(["analyze", str(edited), "--robot", "kobuki", "--report", str(report)]) == 1
    verdict = capsys.readouterr().out.strip().splitlines()[-1]
    excess_mps = json.loads(report.read_text())["onboard_twist_vs_reference"][
        "max_linear_excess_mps"]
    assert excess_mps > 0.0
    said = re.search(r"speeds by up to ([0-9.e+-]+) mm/s, ([0-9.e+-]+) mrad/s", verdict)
    assert said is not None, verdict  # was "by up to 0.000 m/s, 0.000 rad/s"
    assert float(said.group(1)) > 0.0, verdict
    assert abs(float(said.group(1)) - excess_mps * 1e3) <= 0.005 * excess_mps * 1e3, verdict
