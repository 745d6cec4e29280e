"""`odocan replay` of a log cut mid-drive, or with a hole the recorder left (issue #11 point 4).

Found by the user trial:

* a log cut mid-drive (``sed -n '1000,$p'``) held 861 on-board poses, but the replayed firmware
  started its pose schedule on the log's first encoder frame, so its poses named even ticks and
  the log's odd ones: "the log has no on-board pose to compare with", then PASS, exit 0 — a
  replay that compared nothing, and a firmware departing from the log's passed the same way;
* a hole the recorder left in a clean log (11 s, the 16-bit counters of kobuki wrap over it):
  the replayed firmware, fed no frame for it, takes one wrapped step the recording firmware never
  took, and replay FAILed a correct firmware ("its heading differs from the log's by up to
  24306 mrad").

The verdicts are proven with the independent checker (tests/independent_checker.py: float64
odometry and cantools, nothing of host.judge): the clean log's firmware follows exact odometry
from power-up (so any cut of its log is a correct firmware's), and the euler log's firmware does
not follow exact odometry (so the exact firmware replayed on it departs from it).
"""

from __future__ import annotations

import json
import re
from pathlib import Path
from typing import Any

import pytest

from odocan.host.cli.app import main
from odocan.sim.robot import load
from tests.independent_checker import Robot, check


@pytest.fixture(scope="module")
def drives(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """Two 20 s kobuki drives from power-up (seed 7): one by the exact integrator, one by euler;
    the independent checker says the first is right for exact and the second is not."""
    folder = tmp_path_factory.mktemp("cut")
    logs = {name: folder / f"{name}.log" for name in ("exact", "euler")}
    for name, log in logs.items():
        assert main(["run", "--robot", "kobuki", "--duration", "20", "--seed", "7",
                     "--integrator", name, "--log", str(log)]) == 0
    robot = Robot(**load("kobuki").firmware_params())
    assert check(logs["exact"], robot, "exact", at_power_up).passed
    assert check(logs["euler"], robot, "euler", at_power_up).passed
    assert not check(logs["euler"], robot, "exact", at_power_up).passed
    return logs


def at_power_up(_t_s: float) -> tuple[float, float, float]:
    """The firmware's pose at the log's first encoder frame: (0, 0, 0), from power-up."""
    return (0.0, 0.0, 0.0)


def _lines(path: Path) -> list[str]:
    return path.read_text().splitlines(keepends=True)


def _replay(log: Path, report: Path, *extra: str) -> tuple[int, dict[str, Any]]:
    code = main(["replay", str(log), "--robot", "kobuki", "--report", str(report), *extra])
    return code, json.loads(report.read_text())["replay"]["onboard_vs_log"]


@pytest.mark.parametrize("first_line", [1000, 1003])
def test_a_log_cut_mid_drive_is_compared_pose_by_pose(
    drives: dict[str, Path], tmp_path: Path, first_line: int,
    capsys: pytest.CaptureFixture[str],
) -> None:
    cut = tmp_path / "mid.log"
    cut.write_text("".join(_lines(drives["exact"])[first_line - 1:]))
    capsys.readouterr()
    code, vs_log = _replay(cut, tmp_path / "r.json")
    out = capsys.readouterr().out
    assert code == 0, out
    samples = vs_log["samples"]
    assert isinstance(samples, int)
    assert samples > 800, out  # the trial's cut: 0 compared
    assert samples >= vs_log["logged"] - 2  # every pose, but one naming a frame before the cut
    assert vs_log["log_starts_mid_drive"] is True
    assert "the log starts mid-drive" in out
    # the firmware that departs from the one that recorded the log: FAIL, exit 1
    cut.write_text("".join(_lines(drives["euler"])[first_line - 1:]))
    capsys.readouterr()
    code, vs_log = _replay(cut, tmp_path / "r.json", "--integrator", "exact")
    out = capsys.readouterr().out
    assert code == 1, out
    assert "between gaps of the log its position moves off the log's by up to" in out


def test_a_hole_the_counters_wrap_over_fails_no_correct_firmware(
    drives: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    lines = _lines(drives["exact"])
    holed = tmp_path / "hole.log"
    holed.write_text("".join(lines[:2999] + lines[6999:]))  # sed '3000,6999d': ~11 s lost
    capsys.readouterr()
    code, vs_log = _replay(holed, tmp_path / "r.json")
    out = capsys.readouterr().out
    assert code == 0, out
    holes = vs_log["holes"]
    assert isinstance(holes, list)
    assert len(holes) == 1
    assert f"the log has a hole at t={holes[0]['t_s']:.2f} s" in out
    assert vs_log["max_position_drift_between_gaps_m"] == 0.0
    # the departing firmware still FAILs after the hole
    lines = _lines(drives["euler"])
    holed.write_text("".join(lines[:2999] + lines[6999:]))
    capsys.readouterr()
    code, _ = _replay(holed, tmp_path / "r.json", "--integrator", "exact")
    assert code == 1, capsys.readouterr().out


def test_a_replay_that_pairs_none_of_the_logs_poses_is_unjudged(
    drives: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A log whose recorder kept only the encoder frames no pose names (every other one): its
    1000 poses name frames the replay is not fed, so nothing can be compared: exit 1."""
    kept, encoders = [], 0
    for line in _lines(drives["exact"]):
        if " 100#" in line:
            encoders += 1
            if encoders % 2:  # the 1st, 3rd, ... encoder frames: the poses name the others
                continue
        kept.append(line)
    thinned = tmp_path / "thinned.log"
    thinned.write_text("".join(kept))
    capsys.readouterr()
    code, vs_log = _replay(thinned, tmp_path / "r.json")
    out = capsys.readouterr().out
    assert (code, vs_log["samples"]) == (1, 0), out
    assert out.splitlines()[-1].startswith("UNJUDGED: none of the log's 1000 on-board poses")


def test_the_first_line_says_what_was_compared_as_the_verdict_judges_it(
    drives: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """The trial (issue #11, rule 6): a log with a recorder hole printed "max difference
    220.4108 mm" (the raw difference across the hole, which no verdict judges) and then PASS;
    a log cut mid-drive printed "0 identical". The first line now names what was compared: the
    positions up to the first gap as they are, after it by their drift, the headings less
    their offset; every figure on it of a PASS is within the tolerance (0.1 mm)."""
    lines = _lines(drives["exact"])
    holed = tmp_path / "hole.log"
    holed.write_text("".join(lines[:2999] + lines[6999:]))
    cut = tmp_path / "mid.log"
    cut.write_text("".join(lines[999:]))
    for log, says in ((holed, "up to the log's first gap as they are"),
                      (cut, "of a log cut mid-drive by their position drift")):
        capsys.readouterr()
        code, vs_log = _replay(log, tmp_path / "r.json")
        first = capsys.readouterr().out.splitlines()[0]
        assert code == 0, first
        assert says in first
        assert " 0 identical" not in first
        figures_mm = [float(v) for v in re.findall(r"max(?: difference)? ([0-9.]+) mm", first)]
        assert figures_mm, first
        assert max(figures_mm) <= 0.1, first
    assert vs_log["max_position_diff_raw_m"] is None  # the cut: no raw position compared


def test_the_reports_position_figure_is_the_verdicts(drives: dict[str, Path],
                                                     tmp_path: Path) -> None:
    """The JSON's ``max_position_diff_m`` held the raw difference across a recorder hole
    (hundreds of mm on kobuki: the replay takes a wrapped step the recording firmware never
    took) beside a PASS, while the printed line said what the verdict compared: now it is the
    verdict's figure, within the tolerance of a PASS; the raw one is kept, named so."""
    lines = _lines(drives["exact"])
    holed = tmp_path / "hole.log"
    holed.write_text("".join(lines[:2999] + lines[6999:]))
    cut = tmp_path / "mid.log"
    cut.write_text("".join(lines[999:]))
    for log in (holed, cut):
        code, vs_log = _replay(log, tmp_path / "r.json")
        assert code == 0
        judged = [vs_log[key] for key in ("max_position_diff_before_gap_m",
                                          "max_position_drift_between_gaps_m")
                  if vs_log[key] is not None]
        assert judged
        assert vs_log["max_position_diff_m"] == max(judged)
        assert vs_log["max_position_diff_m"] <= 1e-4
    code, vs_log = _replay(holed, tmp_path / "r.json")
    assert vs_log["max_position_diff_raw_m"] > 1e-2  # the wrapped step, not a firmware's fault
