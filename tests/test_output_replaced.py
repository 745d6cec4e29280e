"""An output file overwritten when the write fails part-way keeps the file that was there.

``odocan analyze drive.log --report r.json`` on a full disk (or Ctrl-C while the report was
written) removed the part it wrote (test_partial_output.py) -- and with it last run's
``r.json``: the truncating open had already destroyed it. A user expects an interrupted
overwrite to leave the previous file. Each single-file output is now written beside its path and
renamed onto it when whole (``host.outputs.replaced``). Failures are made as in
test_partial_output.py: RLIMIT_FSIZE with SIGXFSZ ignored turns a write past it into EFBIG.
"""

from __future__ import annotations

import os
import stat
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from odocan.host.mqtt.ticktrace import TickTrace
from odocan.host.outputs import OutputError, write_text
from odocan.host.report.junit import Check, write_junit
from odocan.sim.exceptions import Terminated
from tests.limited import limit_file_bytes, run_limited
from tests.test_partial_output import LIMIT_BYTES, signal_mid_write

OLD = b"last night's output, kept\n"


@pytest.fixture(scope="module")
def drive_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A 2 s kobuki drive's candump log."""
    log = tmp_path_factory.mktemp("replaced") / "drive.log"
    subprocess.run([sys.executable, "-m", "odocan", "run", "--robot", "kobuki", "--duration",
                    "2", "--log", str(log)], capture_output=True, timeout=300, check=True)
    return log


def _kept(out: Path, done: subprocess.CompletedProcess[str], option: str, reason: str) -> None:
    """The older file byte for byte, no temporary file beside it, one line saying so, exit 2."""
    assert done.returncode == 2, done.stderr
    assert out.read_bytes() == OLD
    assert [p.name for p in out.parent.iterdir() if p.name.startswith(".")] == []
    assert done.stderr.splitlines() == [
        f"error: {option} {out}: {reason}; the partial file removed, the one there before kept"]


@pytest.mark.parametrize("option", ["--report", "--junit", "--mcap", "--plot"])
def test_a_full_disk_keeps_the_older_output(drive_log: Path, tmp_path: Path, option: str) -> None:
    """Before: the older file was gone (truncated, then the part removed)."""
    name = {"--report": "r.json", "--junit": "j.xml", "--mcap": "m.mcap", "--plot": "p.png"}
    out = tmp_path / name[option]
    out.write_bytes(OLD)
    done = run_limited(["analyze", str(drive_log), "--robot", "kobuki", option, str(out)],
                       file_bytes=LIMIT_BYTES)
    assert "PASS" in done.stdout
    reason = "File too large" if option != "--mcap" else done.stderr.split(": ", 2)[2].split(";")[0]
    _kept(out, done, option, reason)


@pytest.mark.parametrize(("option", "argv"), [
    ("--latency-plot", ["run", "--firmware", "python", "--duration", "1", "-b", "500000"]),
    ("--plot", ["umbmark", "--runs", "1", "--side", "0.2"]),
])
def test_a_full_disk_keeps_the_older_plot(tmp_path: Path, option: str, argv: list[str]) -> None:
    out = tmp_path / "plot.png"
    out.write_bytes(OLD)
    done = run_limited([*argv, option, str(out)], file_bytes=LIMIT_BYTES)
    _kept(out, done, option, "File too large")


def test_a_signal_mid_write_keeps_the_older_report(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """SIGTERM (Ctrl-C alike) after part of the new report was written: the older report is
    whole, no part of the new one anywhere, and the interruption goes on to the CLI."""
    report = tmp_path / "r.json"
    report.write_bytes(OLD)
    signal_mid_write(monkeypatch)
    with pytest.raises(Terminated):
        write_text(report, "{" + " " * 1000 + "}\n", "--report")
    monkeypatch.undo()
    assert report.read_bytes() == OLD
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.json"]


def test_a_replaced_file_keeps_its_permissions(tmp_path: Path) -> None:
    """The new file takes the older one's mode (a report kept private stays so)."""
    report = tmp_path / "r.json"
    report.write_bytes(OLD)
    report.chmod(0o600)
    write_text(report, "{}\n", "--report")
    assert report.read_text() == "{}\n"
    assert stat.S_IMODE(report.stat().st_mode) == 0o600


def test_a_symlinked_output_is_written_through_its_link(tmp_path: Path) -> None:
    """A symlink is written through, never replaced by a file (``--report /dev/stdout``)."""
    target = tmp_path / "out.json"
    target.write_bytes(OLD)
    link = tmp_path / "link.json"
    link.symlink_to(target)
    write_text(link, "{}\n", "--report")
    assert link.is_symlink()
    assert target.read_text() == "{}\n"


def test_a_full_disk_with_no_older_file_leaves_none(tmp_path: Path) -> None:
    """No older file: nothing at the path, nor a temporary file (the message as before)."""
    report = tmp_path / "r.json"
    pid = os.fork()
    if pid == 0:  # a child under the limit, so pytest's own files are not limited
        limit_file_bytes(LIMIT_BYTES)
        try:
            write_text(report, "x" * 10_000, "--report")
        except OutputError as exc:
            os._exit(0 if str(exc) == f"--report {report}: File too large; the partial file "
                     f"removed" else 1)
        os._exit(2)
    assert os.waitpid(pid, 0)[1] == 0
    assert list(tmp_path.iterdir()) == []


def _junit(path: Path) -> None:
    write_junit(path, "run", [Check("onboard_vs_reference", False, "x" * 1000)])


def _tick_trace(path: Path) -> None:
    trace = TickTrace(path)
    trace.rows = [{"k": k, "late_ms": 0.0} for k in range(100)]
    trace.write()


@pytest.mark.parametrize("write", [_junit, _tick_trace])
def test_a_signal_mid_write_keeps_the_older_junit_and_tick_trace(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, write: Any
) -> None:
    """``write_junit`` and the fleet's tick trace (``ODOCAN_TICK_TRACE``) wrote in place: a
    signal part-way left the older file cut to the new one's first 100 characters."""
    out = tmp_path / "out.xml"
    out.write_bytes(OLD)
    signal_mid_write(monkeypatch)
    with pytest.raises(Terminated):
        write(out)
    monkeypatch.undo()
    assert out.read_bytes() == OLD
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.xml"]


@pytest.mark.parametrize("write", [_junit, _tick_trace])
def test_a_full_disk_keeps_the_older_junit_and_tick_trace(tmp_path: Path, write: Any) -> None:
    """Past RLIMIT_FSIZE (EFBIG, a full disk alike): the older file whole, no part left, one
    ``OutputError`` (before: the older file cut to the limit, an OSError)."""
    out = tmp_path / "out.xml"
    out.write_bytes(OLD)
    pid = os.fork()
    if pid == 0:  # a child under the limit, so pytest's own files are not limited
        limit_file_bytes(LIMIT_BYTES)
        try:
            write(out)
        except OutputError as exc:
            os._exit(0 if "File too large; the partial file removed, the one there before kept"
                     in str(exc) else 1)
        except BaseException:
            os._exit(3)
        os._exit(2)
    assert os.waitpid(pid, 0)[1] == 0
    assert out.read_bytes() == OLD
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.xml"]
