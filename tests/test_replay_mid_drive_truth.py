"""`odocan replay` of a log cut mid-drive must not compare the replayed pose with the truth.

Found by the user trial (eleventh pass): `odocan run --robot kobuki --duration 20 --log r.log;
sed -n 3001,6000p r.log > cut.log; odocan replay cut.log --robot kobuki` printed

    truth         1563.2745 mm     1453.7737 mm   785.8775 mrad   -785.4940 mrad
    PASS: ...

under a PASS: the replayed firmware starts from (0, 0, 0) on the cut log's first encoder frame
(replay says so), the log's SIM_TRUTH goes on from where the drive was, so the "truth" row
measured the cut's own pose, not any error of the firmware. The same drive's truth row from
power-up is 0.14 mm. A replay mid-drive now leaves the truth out (the row reads "-") and says why
in one line; from power-up the truth is compared as before.

The independent part: the truth at the cut, decoded here with cantools from the shipped DBC, is
metres from (0, 0, 0), so no comparison from (0, 0, 0) can mean anything.
"""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

import can
import cantools
import pytest
from cantools.database.can import Database

from odocan.host.cli.app import main
from odocan.sim import contract

FIRST_LINE = 3001  # 8.3 s into the drive


@pytest.fixture(scope="module")
def drive(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 20 s kobuki drive from power-up (seed 0)."""
    log = tmp_path_factory.mktemp("midtruth") / "r.log"
    assert main(["run", "--robot", "kobuki", "--duration", "20", "--log", str(log)]) == 0
    return log


def _truth_at_start_m(log: Path) -> float:
    """Distance from (0, 0, 0) of the log's first whole SIM_TRUTH position (cantools)."""
    db = cantools.database.load_file(str(contract.DBC_PATH))
    assert isinstance(db, Database)
    truth = db.get_message_by_name("SIM_TRUTH")
    seen: dict[str, float] = {}
    for msg in can.LogReader(str(log)):
        if msg.arbitration_id == truth.frame_id:
            signals = truth.decode(bytes(msg.data), decode_choices=False)
            assert isinstance(signals, dict)
            seen.update({k: float(v) for k, v in signals.items()  # type: ignore[arg-type]
                         if k in ("X", "Y")})
            if len(seen) == 2:
                return math.hypot(seen["X"], seen["Y"])
    raise AssertionError("no SIM_TRUTH position in the log")


def _replay(log: Path, report: Path) -> tuple[int, dict[str, Any]]:
    code = main(["replay", str(log), "--robot", "kobuki", "--report", str(report)])
    return code, json.loads(report.read_text())


def test_a_replay_mid_drive_leaves_the_truth_out(
    drive: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    cut = tmp_path / "cut.log"
    cut.write_text("".join(drive.read_text().splitlines(keepends=True)[FIRST_LINE - 1:]))
    assert _truth_at_start_m(cut) > 0.5  # the cut starts metres from the replay's (0, 0, 0)
    capsys.readouterr()
    code, report = _replay(cut, tmp_path / "r.json")
    out = capsys.readouterr().out
    assert code == 0, out
    assert report["replay"]["onboard_vs_log"]["log_starts_mid_drive"] is True
    assert report["onboard_vs_truth"]["max_position_error_m"] is None, out  # was 1.563 m
    assert report["replay"]["truth_compared"] is False
    assert "the truth is not compared" in out


def test_a_replay_from_power_up_still_compares_the_truth(
    drive: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    code, report = _replay(drive, tmp_path / "r.json")
    out = capsys.readouterr().out
    assert code == 0, out
    error = report["onboard_vs_truth"]["max_position_error_m"]
    assert error is not None, out
    assert error < 1e-3, out
    assert report["replay"]["truth_compared"] is True
    assert "the truth is not compared" not in out
