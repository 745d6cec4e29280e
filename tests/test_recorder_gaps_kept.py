"""The other side of ``host.judge.gapseen`` (rule 5: a FAIL must never blame a correct
firmware): a recorder that dropped encoder frames the firmware saw. The firmware integrated
them one by one, its ENC_E2E_OK counts them and its ENC_E2E_LOST does not grow, so the pages
prove nothing there and the gaps keep ``gapbound``'s allowance: the correct firmware on a 1 cm
robot (steps of a spin merged by the log: centimetres of merge error) PASSes. The same log
judged with the rule made unsafe (every gap taken as missed by the firmware) FAILs: the guard
has teeth. The live judge (the monitor's model and the bridge: ``host.judge.livegapseen``) keeps
the allowance too, and with the unsafe rule withdraws it and FAILs alike.
"""

from __future__ import annotations

import random
import re
from pathlib import Path

import pytest

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.host.judge.gapseen import Seen
from odocan.host.judge.samples import POSITION_LSB_M
from odocan.sim.robot import load
from tests.test_sender_stall_drop import live_judges
from tests.test_sender_stall_step import _streamed
from tests.test_wrap_after_gaps import ONE_CM_TOML

_ENCODERS = re.compile(r"^\(\S+\) \S+ 100#")  # WHEEL_ENCODERS (0x100)


def _recorder_gaps(tmp_path: Path) -> tuple[Path, Path]:
    """A clean 20 s random drive of the 1 cm robot, then its log less runs of 3 to 12 encoder
    frames (a recorder that dropped them; every other frame kept)."""
    robot, log = tmp_path / "pmir1cm.toml", tmp_path / "clean.log"
    robot.write_text(ONE_CM_TOML)
    assert main(["run", "--robot", str(robot), "--scenario", "random", "--duration", "20",
                 "--log", str(log)]) == 0
    rng = random.Random(5)
    lines, kept, skip = log.read_text().splitlines(keepends=True), [], 0
    encoders = 0
    for line in lines:
        if _ENCODERS.match(line):
            encoders += 1
            if skip == 0 and encoders > 200 and rng.random() < 0.02:
                skip = rng.randint(3, 12)
            if skip:
                skip -= 1
                continue
        kept.append(line)
    assert len(kept) < len(lines) - 100
    cut = tmp_path / "recorder.log"
    cut.write_text("".join(kept))
    return cut, robot


def test_gaps_the_firmware_saw_keep_their_allowance(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path, robot = _recorder_gaps(tmp_path)
    result = analyze(read_log(path), load(robot), "exact")
    onboard = result.report["onboard_vs_reference"]
    breaks = result.report["reference_breaks"]
    assert result.passed, (onboard, breaks)
    assert breaks["gap_placements"] >= 10
    assert _streamed(path, tmp_path, str(robot)) == onboard
    for name, tracker in live_judges(path, robot):
        assert "POSE WRONG" not in name
        assert tracker.placer.placements.gaps >= 10, name
        assert tracker.wrongs.count == 0, (name, tracker.wrongs.summary())
    monkeypatch.setattr(Seen, "gap_missed", lambda *_: True)  # an unsafe rule
    unsafe = analyze(read_log(path), load(robot), "exact")
    assert not unsafe.passed
    for name, tracker in live_judges(path, robot):
        assert tracker.placer.withdrawn >= 10, name  # the live judge asks the same rule
        assert tracker.max_beyond_allowance_m > POSITION_LSB_M, name
        assert tracker.wrongs.count >= 1, name
