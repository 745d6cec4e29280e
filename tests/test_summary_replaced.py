"""The text summary says where the reference was re-placed (trial finding F3).

After a gap of the log the reference is re-placed within the gap's allowance (``breaks``): the
position across the gap is judged only within it. The summary said only "start exact from
power-up" while the JSON had ``gap_placements: 1``; a firmware 5 mm off from the gap on PASSed
with nothing in the text to say the judge could not see it. The truth: the same drive without the
gap, by ``tests/independent_checker.py`` (right, and 5 mm wrong from the gap on)."""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

from rich.console import Console

from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import Tolerance, analyze
from odocan.host.report.summary import print_summary
from odocan.sim.robot import load
from tests.independent_checker import check
from tests.synth_log import synthesize, wandering_drive
from tests.test_analysis_reboot import checker_robot

PMIR = load("pmir")
GAP = (300, 331)  # encoder frames the logger missed: 0.31 s
BIAS_LSB = 50  # 5 mm, from the gap on


def _summary(report: dict[str, Any]) -> str:
    out = io.StringIO()
    print_summary(report, Tolerance(), Console(file=out, width=300), title="t")
    return out.getvalue()


def test_a_gap_placement_is_said_with_its_allowance(tmp_path: Path) -> None:
    d_left, d_right = wandering_drive(PMIR, 600, 0.004, seed=7)
    right = synthesize(PMIR, "exact", d_left, d_right)
    wrong = synthesize(PMIR, "exact", d_left, d_right,
                       x_bias_100um={k: BIAS_LSB for k in range(GAP[1], 601)})
    robot = checker_robot(PMIR)
    assert check(right.write(tmp_path / "right.log"), robot, "exact", lambda _t: (0, 0, 0)).passed
    assert not check(wrong.write(tmp_path / "wrong.log"), robot, "exact",
                     lambda _t: (0, 0, 0)).passed
    path = tmp_path / "gap.log"
    path.write_text("".join(wrong.lines(0, GAP[0]) + wrong.lines(GAP[1])))
    report = analyze(read_log(path), PMIR).report
    breaks = report["reference_breaks"]
    assert breaks["gap_placements"] == 1
    absorbed_mm = breaks["max_gap_offset_absorbed_m"] * 1e3
    assert 4.9 < absorbed_mm < 5.1  # the 5 mm went into the placement
    text = _summary(report)
    assert (f"re-placed  1 after a gap of the log (at most {absorbed_mm:.4g} mm absorbed, within "
            f"{breaks['gap_offset_allowance_m'] * 1e3:.4g} mm allowed): the position across it "
            "is judged only within that allowance") in text


def test_no_placement_no_line(tmp_path: Path) -> None:
    d_left, d_right = wandering_drive(PMIR, 300, 0.004, seed=7)
    path = synthesize(PMIR, "exact", d_left, d_right).write(tmp_path / "clean.log")
    report = analyze(read_log(path), PMIR).report
    assert report["passed"]
    text = _summary(report)
    assert "re-placed" not in text
    assert "judged     151 of 151 on-board poses compared with the reference (100 %)" in text
