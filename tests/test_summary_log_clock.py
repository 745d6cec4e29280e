"""The text summary's times count from the log's first frame (trial finding, LOW).

A capture with absolute stamps (``odocan monitor --log``, candump of a real bus: epoch seconds)
made the summary say "DEGRADED POSE_UNCERTAIN since 1796342025.59 s", reboots and stalls "at"
as many seconds. Now the summary says seconds since the log's first frame and names that frame
once (ISO 8601 UTC when absolute); the JSON report keeps bus times (``t_s``, ``since_s``) and
says the first frame's in ``first_frame_s``. The same run's log shifted by python-can must read
the same but for that one line, whole and streamed alike."""

from __future__ import annotations

import json
from datetime import UTC, datetime
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.host.cli.app import main

SHIFT_S = {"epoch": 1.8e9, "uptime": 1234.5}
WHEN = {"epoch": datetime(2027, 1, 15, 8, 0, tzinfo=UTC).isoformat(timespec="milliseconds")
        .replace("+00:00", "Z"), "uptime": "at bus time 1234.500 s"}


@pytest.fixture(scope="module")
def logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A square drive with a reboot at 5 s and a stall at 8 s (ends DEGRADED POSE_UNCERTAIN), its
    log as recorded and shifted by each of ``SHIFT_S`` (python-can reads and writes it)."""
    out = tmp_path_factory.mktemp("clock")
    paths = {"run": out / "run.log"}
    assert main(["run", "--scenario", "square", "--duration", "12", "--faults",
                 "reboot=5,stall=8:0.5", "--log", str(paths["run"])]) == 0
    for name, shift_s in SHIFT_S.items():
        paths[name] = out / f"{name}.log"
        with can.LogReader(str(paths["run"])) as reader, can.Logger(str(paths[name])) as writer:
            for message in reader:
                message.timestamp += shift_s
                writer.on_message_received(message)
    return paths


def _analyzed(log: Path, stream: str, tmp_path: Path,
              capsys: pytest.CaptureFixture[str]) -> tuple[list[str], dict[str, Any]]:
    """The summary's lines past its title (which names the log) and the JSON report."""
    report = tmp_path / f"{log.stem}-{stream}.json"
    capsys.readouterr()
    assert main(["analyze", str(log), "--stream", stream, "--report", str(report)]) == 0
    return capsys.readouterr().out.splitlines()[1:], json.loads(report.read_text())


@pytest.mark.parametrize("name", list(SHIFT_S))
def test_a_shifted_log_reads_as_the_recorded_one_but_its_first_frame_line(
        logs: dict[str, Path], name: str, tmp_path: Path,
        capsys: pytest.CaptureFixture[str]) -> None:
    plain, plain_report = _analyzed(logs["run"], "never", tmp_path, capsys)
    assert not [line for line in plain if line.strip().startswith("log ")]  # from 0: as before
    assert any("restarted at 5.00 s" in line for line in plain)  # what the log holds
    assert any("ends DEGRADED POSE_UNCERTAIN since " in line for line in plain)
    said: dict[str, tuple[list[str], dict[str, Any]]] = {}
    for stream in ("never", "always"):
        said[stream] = _analyzed(logs[name], stream, tmp_path, capsys)
    assert said["never"] == said["always"]  # whole and streamed: one text, one report
    lines, report = said["never"]
    extra = f"  log        first frame {WHEN[name]}; the times below are seconds since it"
    assert extra in lines
    lines.remove(extra)
    assert lines == plain
    assert report["first_frame_s"] == SHIFT_S[name]
    assert plain_report["first_frame_s"] == 0.0
    for key in ("reboots", "events", "firmware_events"):  # the report's times stay bus times
        want = [e["t_s"] + SHIFT_S[name] for e in plain_report[key]]
        assert [e["t_s"] for e in report[key]] == pytest.approx(want, abs=1e-5)
