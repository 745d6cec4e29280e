"""Outputs that fail while being written name their path, in one line, and lose nothing else.

Found from outside on a disk that fills up (a 64 kB tmpfs): ``odocan run --log x.log`` died
with ``error: [Errno 28] No space left on device`` -- no path, no summary of the hour it had
simulated -- and ``--mcap`` printed one ``error logging message`` line per message (4 835 lines
for a 10 s drive) before its error. Here the full disk is a python-can writer whose file
refuses every write after a few thousand bytes (ENOSPC), as the kernel's does.
"""

from __future__ import annotations

import errno
import io
import os
import subprocess
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.host.cli.app import main
from tests.limited import run_limited

ROOT = Path(__file__).resolve().parents[1]


class _FullDisk(io.StringIO):
    """A text file that takes ``room`` characters, then fails like a full disk."""

    def __init__(self, room: int) -> None:
        super().__init__()
        self.room = room

    def write(self, text: str) -> int:
        if self.tell() + len(text) > self.room:
            raise OSError(errno.ENOSPC, "No space left on device")
        return super().write(text)


def _logger_on_a_full_disk(room: int) -> Any:
    real = can.Logger

    def make(path: Path, *args: Any, **kwargs: Any) -> Any:
        writer: Any = real(path, *args, **kwargs)
        writer.file.close()
        writer.file = _FullDisk(room)
        return writer

    return make


def test_run_log_on_a_full_disk_names_the_path_and_keeps_the_summary(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    log = tmp_path / "drive.log"
    monkeypatch.setattr(can, "Logger", _logger_on_a_full_disk(4000))
    code = main(["run", "--duration", "2", "--log", str(log)])
    out, err = capsys.readouterr()
    assert code == 2, err
    assert "PASS: on-board vs reference" in out  # the run went on and was judged
    lines = err.splitlines()
    assert lines[-1].startswith(f"error: --log {log}: No space left on device (recording "
                                "stopped after "), err
    frames = int(lines[-1].split("stopped after ")[1].split()[0])
    assert 0 < frames < 4000 // 30  # candump lines are ~40 characters: cut early, counted
    assert "Traceback" not in err


def test_replay_log_on_a_full_disk_names_the_path(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    """``odocan replay --log`` on a full disk said ``error: [Errno 28] No space left on
    device``: no path (found on a 64 kB tmpfs)."""
    drive, log = tmp_path / "drive.log", tmp_path / "replayed.log"
    assert main(["run", "--duration", "2", "--log", str(drive)]) == 0
    capsys.readouterr()
    monkeypatch.setattr(can, "Logger", _logger_on_a_full_disk(4000))
    code = main(["replay", str(drive), "--log", str(log)])
    _, err = capsys.readouterr()
    assert code == 2, err
    assert err.splitlines()[-1].startswith(f"error: --log {log}: No space left on device "
                                           "(recording stopped after "), err
    assert "Traceback" not in err


class _BusThenCtrlC(can.BusABC):
    """A bus that hears ``frames`` encoder frames, then gets Ctrl-C."""

    def __init__(self, frames: int) -> None:
        self.left = frames
        super().__init__(channel="then-ctrl-c")

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        if self.left == 0:
            raise KeyboardInterrupt
        self.left -= 1
        return can.Message(arbitration_id=0x100, data=bytes(8), is_extended_id=False), False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        raise NotImplementedError


def test_monitor_json_is_kept_when_its_recording_fills_the_disk(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    import json

    from odocan.host.cli.subparsers import monitor as monitor_cmd

    log = tmp_path / "heard.log"
    monkeypatch.setattr(can, "Logger", _logger_on_a_full_disk(2000))
    monkeypatch.setattr(monitor_cmd, "open_bus", lambda args: _BusThenCtrlC(300))
    code = main(["monitor", "-i", "virtual", "--json", "--log", str(log)])
    out, err = capsys.readouterr()
    assert code == 2, err
    assert json.loads(out)["frames_total"] == 300  # what was heard is shown
    last = err.splitlines()[-1]
    assert last.startswith(f"error: --log {log}: recording stopped after "), err
    assert last.endswith("No space left on device"), err


def _odocan_with_file_size_limit(limit_bytes: int, *argv: str) -> subprocess.CompletedProcess[str]:
    """``python -m odocan ARGV`` in a process whose files cannot grow past ``limit_bytes``
    (RLIMIT_FSIZE, SIGXFSZ ignored: a write past it fails with EFBIG, as a full disk fails with
    ENOSPC) -- a disk that fills, without privileges."""

    return run_limited(list(argv), file_bytes=limit_bytes, cwd=ROOT,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})


@pytest.mark.parametrize("command", ["run", "analyze"])
def test_mcap_on_a_full_disk_is_one_line_naming_the_path_after_the_summary(
    command: str, tmp_path: Path
) -> None:
    path = tmp_path / "drive.mcap"
    argv = ["run", "--duration", "10"]
    if command == "analyze":
        log = tmp_path / "drive.log"
        assert main([*argv, "--log", str(log)]) == 0
        argv = ["analyze", str(log)]
    done = _odocan_with_file_size_limit(20_000, *argv, "--mcap", str(path))
    assert done.returncode == 2, done.stderr
    assert done.stderr == (  # was 4 835 lines; then the truncated MCAP stayed
        f"error: --mcap {path}: File too large; the partial file removed\n"
    )
    assert not path.exists()
    assert "PASS: on-board vs reference" in done.stdout  # the verdict is not lost


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> Path:
    log = tmp_path_factory.mktemp("recorded") / "drive.log"
    assert main(["run", "--duration", "1", "--log", str(log)]) == 0
    return log


@pytest.mark.parametrize(
    ("command", "option"),
    [("analyze", "--report"), ("analyze", "--junit"), ("analyze", "--mcap"),
     ("replay", "--junit"), ("replay", "--log"), ("replay", "--report")],
)
def test_an_output_on_the_input_log_is_refused_and_the_log_kept(
    command: str, option: str, recorded: Path, tmp_path: Path,
    capsys: pytest.CaptureFixture[str],
) -> None:
    """``analyze drive.log --report drive.log`` replaced the recording with its JSON report;
    ``replay drive.log --log drive.log`` with the replayed bus."""
    log = tmp_path / "drive.log"
    log.write_bytes(recorded.read_bytes())
    capsys.readouterr()
    alias = tmp_path / "." / "drive.log"  # the same file by another spelling
    code = main([command, str(log), option, str(alias)])
    out, err = capsys.readouterr()
    assert code == 2, out
    assert err == (f"error: {option} {alias}: that is LOG {log}, the input: it would be "
                   "overwritten\n")
    assert log.read_bytes() == recorded.read_bytes()


def test_two_outputs_of_a_run_on_one_file_are_refused(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``run --log out --report out``: the report replaced the hour's log at the end."""
    out_path = tmp_path / "out.log"
    code = main(["run", "--duration", "1", "--log", str(out_path), "--junit", str(out_path)])
    out, err = capsys.readouterr()
    assert code == 2, out
    assert err == f"error: --junit {out_path}: that is --log {out_path}, also an output\n"
    assert not out_path.exists()


def test_key_derive_never_writes_over_the_fleet_key(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """``key derive --fleet-key K --out K --force`` replaced the fleet's secret with one
    robot's key, exit 0: every other robot's key is lost with it."""
    fleet_key = tmp_path / "fleet.key"
    fleet_key.write_text("00112233445566778899aabbccddeeff\n")
    fleet_key.chmod(0o600)
    code = main(["key", "derive", "--fleet-key", str(fleet_key), "--robot", "robot001",
                 "--out", str(fleet_key), "--force"])
    out, err = capsys.readouterr()
    assert code == 2, out
    assert err == (f"error: --out {fleet_key}: that is --fleet-key {fleet_key}, the input: it "
                   "would be overwritten\n")
    assert fleet_key.read_text() == "00112233445566778899aabbccddeeff\n"


@pytest.mark.parametrize(("option", "name", "limit_bytes"),
                         [("--report", "drive.json", 3_000), ("--junit", "drive.xml", 500)])
def test_a_run_whose_log_and_report_both_fail_names_both(
    tmp_path: Path, option: str, name: str, limit_bytes: int
) -> None:
    """The disk fills while recording, and the report cannot be written either: the one error
    line named the report only, and the recording that stopped part-way went unsaid (a 0-byte
    ``--log`` on a full tmpfs, exit 2 for the report; the JUnit file's error hid it too). Now the
    line names the log first (its partial file is kept: what it holds is good), then the other."""
    log, report = tmp_path / "drive.log", tmp_path / name
    done = _odocan_with_file_size_limit(
        limit_bytes, "run", "--duration", "2", "--log", str(log), option, str(report)
    )
    assert done.returncode == 2, done.stderr
    assert "PASS: on-board vs reference" in done.stdout
    lines = done.stderr.splitlines()
    assert len(lines) == 1, lines
    assert lines[0].startswith(f"error: --log {log}: File too large"), lines
    assert f"; {option} {report}: File too large" in lines[0], lines
    assert 0 < log.stat().st_size <= limit_bytes
    assert not report.exists()
