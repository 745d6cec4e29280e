"""The firmware's final state is in the verdict (issue #11).

Found in review: a run whose bus-off made the firmware merge a step past its 50 mm bound PASSed
(the pose is right) while the firmware ended DEGRADED POSE_UNCERTAIN, latched until a set-pose;
the JSON's ``firmware_events`` said so, the text summary read as a plain PASS. Now ``run`` and
``analyze`` (whole and streamed) add one ``firmware`` line and the JSON a ``firmware_final``;
a firmware that ends OK adds nothing to the text. The expected state is read from the log's
last ODOM_STATUS summary with cantools (nothing of the judges)."""

from __future__ import annotations

import json
from pathlib import Path

import can
import pytest

from odocan.host.cli.app import main
from odocan.sim.contract import DBC_PATH
from tests.dbc_typed import decode, load_can_dbc, number

STATUS_ID = 0x380  # ODOM_STATUS


def _final_by_cantools(log: Path) -> tuple[str, str, float]:
    """STATE and REASON of the log's last summary page and the bus time of the first summary of
    the run of summaries saying both up to the end."""
    db = load_can_dbc(DBC_PATH)
    said: list[tuple[str, str, float]] = []
    with can.LogReader(log) as reader:
        for m in reader:
            if m.arbitration_id != STATUS_ID:
                continue
            s = decode(db, STATUS_ID, m.data)
            if number(decode(db, STATUS_ID, m.data, decode_choices=False)["PAGE"]) == 0:
                said.append((str(s["STATE"]), str(s["REASON"]), float(m.timestamp)))
    state, reason, since_s = said[-1]
    for s_state, s_reason, t_s in reversed(said):
        if (s_state, s_reason) != (state, reason):
            break
        since_s = t_s
    return state, reason, since_s


@pytest.fixture(scope="module")
def latched(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A 6 s straight drive bus-off from 2 s for 1 s: the merged step latches POSE_UNCERTAIN."""
    out = tmp_path_factory.mktemp("final")
    log, report = out / "busoff.log", out / "run.json"
    assert main(["run", "--scenario", "straight", "--duration", "6", "--faults",
                 "busoff=2:1", "--log", str(log), "--report", str(report)]) == 0
    return {"log": log, "report": report}


def _firmware_lines(text: str) -> list[str]:
    return [line.strip() for line in text.splitlines() if line.strip().startswith("firmware ")]


def test_the_log_ends_degraded_pose_uncertain(latched: dict[str, Path]) -> None:
    state, reason, _ = _final_by_cantools(latched["log"])
    assert (state, reason) == ("DEGRADED", "POSE_UNCERTAIN")


@pytest.mark.parametrize("how", ["run", "never", "always"])
def test_a_pass_that_ends_degraded_says_so(
    latched: dict[str, Path], how: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    capsys.readouterr()  # the fixture's run printed before
    if how == "run":  # run again for its text
        report = tmp_path / "run.json"
        assert main(["run", "--scenario", "straight", "--duration", "6", "--faults",
                     "busoff=2:1", "--report", str(report)]) == 0
    else:
        report = tmp_path / "analyze.json"
        assert main(["analyze", str(latched["log"]), "--stream", how,
                     "--report", str(report)]) == 0
    state, reason, since_s = _final_by_cantools(latched["log"])
    out = capsys.readouterr().out
    assert "PASS" in out
    assert _firmware_lines(out) == [
        f"firmware   ends {state} {reason} since {since_s:.2f} s: steps merged across lost "
        "encoder periods may have put the pose more than 50 mm off (their path is unknowable); "
        "DEGRADED until a set-pose"]
    final = json.loads(report.read_text())["firmware_final"]
    assert (final["state"], final["reason"]) == (state, reason)
    assert final["since_s"] == pytest.approx(since_s, abs=1e-6)


def test_a_clean_run_adds_no_line(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    log, report = tmp_path / "clean.log", tmp_path / "clean.json"
    assert main(["run", "--scenario", "straight", "--duration", "3", "--log", str(log),
                 "--report", str(report)]) == 0
    out = capsys.readouterr().out
    assert _firmware_lines(out) == []
    state, reason, since_s = _final_by_cantools(log)
    assert (state, reason) == ("OK", "NONE")
    final = json.loads(report.read_text())["firmware_final"]
    assert (final["state"], final["reason"]) == ("OK", "NONE")
    assert final["since_s"] == pytest.approx(since_s, abs=1e-6)
