"""A silence the 4-bit COUNTER cannot count is said, not hidden in "lost" (issue #11, rule 6).

Found by the outside trial: a 20 s bus-off left 2000 WHEEL_ENCODERS frames missing and the E2E
table said "lost 1" (the COUNTER's step mod 16), while the frames column was right. The count
stays what the COUNTER tells; a silence of 16 periods or more makes it a lower bound, said
"≥ 1" with the silence's length, the same in analyze's report and text, the monitor's live
receiver and its table. The frames missing are counted here from the log's own timestamps
(nothing of the judges)."""

from __future__ import annotations

import io
import itertools
import json
from pathlib import Path

import can
import pytest
from rich.console import Console

from odocan.host.cli.app import main
from odocan.host.protocol.e2e_live import E2EMonitor
from odocan.host.report.live import messages_table

ENCODER_ID, ENCODER_CYCLE_S = 0x100, 0.01


@pytest.fixture(scope="module")
def busoff(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A 12 s straight drive whose transmitters are bus-off from 3 s for 5 s."""
    out = tmp_path_factory.mktemp("silence")
    log, report = out / "busoff.log", out / "run.json"
    assert main(["run", "--scenario", "straight", "--duration", "12", "--faults",
                 "busoff=3:5", "--log", str(log), "--report", str(report)]) == 0
    return {"log": log, "report": report}


def _encoder_times_s(log: Path) -> list[float]:
    with can.LogReader(log) as reader:
        return [m.timestamp for m in reader if m.arbitration_id == ENCODER_ID]


def test_a_silence_is_said_with_its_length_and_lost_as_a_lower_bound(
    busoff: dict[str, Path], tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    times_s = _encoder_times_s(busoff["log"])
    steps_s = [b - a for a, b in itertools.pairwise(times_s)]
    longest_s = max(steps_s)
    missing = round(longest_s / ENCODER_CYCLE_S) - 1
    assert missing > 400  # the bus-off: ~5 s of encoder frames
    report = tmp_path / "analyze.json"
    capsys.readouterr()
    assert main(["analyze", str(busoff["log"]), "--report", str(report)]) == 0
    out = capsys.readouterr().out
    counts = json.loads(report.read_text())["e2e"]["WHEEL_ENCODERS"]
    assert counts["lost"] < missing  # what the COUNTER can tell: a lower bound
    assert counts["silences"] == 1
    assert counts["silence_ms"] == pytest.approx(longest_s * 1e3, abs=1)
    row = next(line for line in out.splitlines() if line.lstrip().startswith("WHEEL_ENCODERS"))
    assert row.split()[3:5] == ["≥", str(counts["lost"])], row
    words = " ".join(out.split())  # the caption wraps at the table's width
    assert "lost ≥: silent up to 5." in words
    assert "longer than a COUNTER cycle (16 periods): the frames lost then are not counted" in words
    assert counts == json.loads(busoff["report"].read_text())["e2e"]["WHEEL_ENCODERS"]


def test_the_monitors_receiver_and_table_say_the_same_silence(
    busoff: dict[str, Path], tmp_path: Path
) -> None:
    report = tmp_path / "analyze.json"
    assert main(["analyze", str(busoff["log"]), "--report", str(report)]) == 0
    analyzed = json.loads(report.read_text())["e2e"]
    live = E2EMonitor()
    with can.LogReader(busoff["log"]) as reader:
        for msg in reader:
            live.check(msg.arbitration_id, bytes(msg.data), extended=msg.is_extended_id,
                       timestamp_s=msg.timestamp)
    heard = live.counts()
    for name in ("WHEEL_ENCODERS", "ODOM_POSE_X", "ODOM_STATUS"):
        assert {k: heard[name].get(k) for k in ("lost", "silences", "silence_ms")} == {
            k: analyzed[name].get(k) for k in ("lost", "silences", "silence_ms")}, name
    snapshot = {"messages": {"WHEEL_ENCODERS": {
        "id": "0x100", "count": 700, "rate_hz": 100.0, "jitter_ms": 0.0,
        "e2e": heard["WHEEL_ENCODERS"]}}}
    console = Console(file=io.StringIO(), width=120)
    console.print(messages_table(snapshot, {}))
    text = console.file.getvalue()  # type: ignore[attr-defined]
    assert f"≥ {heard['WHEEL_ENCODERS']['lost']}" in text
    assert "lost ≥: silent up to 5." in text
