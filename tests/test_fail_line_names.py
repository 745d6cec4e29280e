"""A FAIL line names the check that failed (issue #11: a verdict a test engineer can trust).

The outside trial of the twenty-ninth pass: X raised 10 mm from the first pose after a stall
FAILed analyze on the poses sent first after a silence alone (``stall_first_pose``), and the line
said only "on-board vs reference within 0.1 mm ... " with no "not met": nothing named a failed
check. The same drive untouched PASSes with the same words."""

from __future__ import annotations

from pathlib import Path

import pytest

from odocan.host.cli.app import main
from tests.judges_cli import raise_x_10_mm

DRIVE = ["run", "--robot", "kobuki", "--scenario", "straight", "--seed", "406", "--duration", "8",
         "--faults", "drop=0.05,stall=2.5:0.6"]
RAISED_FROM_S = 3.101  # the first pose after the stall


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    work = tmp_path_factory.mktemp("failline")
    log, raised = work / "drive.log", work / "raised.log"
    assert main([*DRIVE, "--log", str(log)]) == 0
    raise_x_10_mm(log, raised, RAISED_FROM_S)
    return log, raised


@pytest.mark.parametrize("stream", ["never", "always"])
def test_the_fail_line_names_the_first_pose_after_the_stall(
    logs: tuple[Path, Path], stream: str, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    assert main(["analyze", str(logs[1]), "--stream", stream]) == 1
    line = next(x for x in capsys.readouterr().out.splitlines() if x.startswith("FAIL"))
    assert "beyond any the firmware can resume at after its stall" in line, line
    assert "(the pose criterion is met" in line  # the pose criterion itself passed


def test_the_untouched_drive_passes_without_it(
    logs: tuple[Path, Path], capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()
    assert main(["analyze", str(logs[0])]) == 0
    out = capsys.readouterr().out
    assert "PASS" in out
    assert "resume at after its stall" not in out
