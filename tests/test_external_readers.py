"""Logs written by ``odocan run --log`` read back by other people's tools.

* python-can's ``can.LogReader`` reads the .log (candump), .asc and .blf of one run as the same
  frames with the same data and timestamps, as many as the run's report counted;
* the cantools CLI (``python -m cantools decode dbc/odocan.dbc < run.log``) decodes every frame,
  each as the message its ID names in the DBC, none unknown;
* can-utils' ``log2asc`` converts the .log into an ASC file python-can reads back as the same frames
  (skipped where can-utils is not installed; CI installs it).
"""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import can
import pytest

from odocan.host.cli.app import main
from tests.dbc_typed import load_can_dbc
from tests.requires import require_executables

ROOT = Path(__file__).resolve().parents[1]
DBC = ROOT / "dbc" / "odocan.dbc"
SUFFIXES = (".log", ".asc", ".blf")
Frame = tuple[float, int, bytes]


@pytest.fixture(scope="module")
def run_logs(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """One 4 s figure8 run (seed 5), logged in each format; key "report" is its JSON report."""
    folder = tmp_path_factory.mktemp("external")
    paths = {suffix: folder / f"run{suffix}" for suffix in SUFFIXES}
    for suffix, path in paths.items():
        argv = [
            "run",
            "--scenario",
            "figure8",
            "--duration",
            "4",
            "--seed",
            "5",
            "--log",
            str(path),
            "--report",
            str(folder / f"run{suffix}.json"),
        ]
        assert main(argv) == 0
    paths["report"] = folder / "run.log.json"
    return paths


def read_frames(path: Path) -> list[Frame]:
    """(timestamp rounded to 1 us, ID, data) of every frame python-can reads from ``path``."""
    return [
        (round(msg.timestamp, 6), msg.arbitration_id, bytes(msg.data))
        for msg in can.LogReader(path)
    ]


def test_python_can_reads_every_format_alike(run_logs: dict[str, Path]) -> None:
    frames = {suffix: read_frames(run_logs[suffix]) for suffix in SUFFIXES}
    report = json.loads(run_logs["report"].read_text())
    assert len(frames[".log"]) == sum(report["frames"].values())
    assert sum(frame_id == 0x100 for _, frame_id, _ in frames[".log"]) == 400
    assert frames[".asc"] == frames[".log"]
    assert frames[".blf"] == frames[".log"]
    assert all(len(data) == 8 for _, _, data in frames[".log"])
    assert 3.98 <= frames[".log"][-1][0] < 4.0  # the last 10 ms tick of a 4 s run


def test_python_can_reads_what_the_run_counted(run_logs: dict[str, Path]) -> None:
    db = load_can_dbc(DBC)
    report = json.loads(run_logs["report"].read_text())
    counts: dict[str, int] = {}
    for _, frame_id, _ in read_frames(run_logs[".blf"]):
        name = db.get_message_by_frame_id(frame_id).name
        counts[name] = counts.get(name, 0) + 1
    assert counts == report["frames"]


def test_cantools_decode_knows_every_frame(run_logs: dict[str, Path]) -> None:
    log = run_logs[".log"]
    with log.open("rb") as stdin:
        result = subprocess.run(
            [sys.executable, "-m", "cantools", "decode", "--single-line", str(DBC)],
            stdin=stdin,
            capture_output=True,
            check=False,
            timeout=120,
        )
    assert result.returncode == 0, result.stderr.decode()
    decoded = result.stdout.decode().splitlines()
    report = json.loads(run_logs["report"].read_text())
    assert len(decoded) == len(log.read_text().splitlines()) == sum(report["frames"].values())
    db = load_can_dbc(DBC)
    pattern = re.compile(r"\(\d+\.\d{6}\) vcan0 ([0-9A-F]{3})#[0-9A-F]{16} R :: (\w+)\((.*)\)")
    for line in decoded:
        match = pattern.fullmatch(line)
        assert match, line
        frame_id, name, signals = match.groups()
        assert name == db.get_message_by_frame_id(int(frame_id, 16)).name, line
        assert "CHECKSUM: " in signals, line
        assert "COUNTER: " in signals, line
    assert "Unknown frame id" not in result.stdout.decode()


def test_log2asc_converts_the_log(run_logs: dict[str, Path], tmp_path: Path) -> None:
    require_executables("log2asc", install="apt-get install can-utils")
    converted = tmp_path / "log2asc.asc"
    subprocess.run(
        ["log2asc", "-I", str(run_logs[".log"]), "-O", str(converted), "vcan0"],
        check=True,
        timeout=60,
    )
    original = read_frames(run_logs[".log"])
    frames = read_frames(converted)
    assert [f[1:] for f in frames] == [f[1:] for f in original]
    # log2asc counts time from the first frame stamped 1 s or later after the epoch (our
    # simulated clock starts at 0): from there on, the spacing of the frames is the original's.
    first = next(i for i, f in enumerate(original) if f[0] >= 1.0)
    offset = original[first][0] - frames[first][0]
    assert [round(f[0] + offset, 6) for f in frames[first:]] == [f[0] for f in original[first:]]
