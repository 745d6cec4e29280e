"""``odocan run --log`` on a full disk says how many frames the file holds, and holds them whole.

``recording stopped after N frames`` counted the frames handed to python-can's writer before
the write that failed: measured under RLIMIT_FSIZE (a real EFBIG, as ENOSPC, from the kernel),
N was 11 where the candump file held 125 whole lines, 2531 where it held 2500 and a cut line,
2730 where a ``.blf`` read back 449 -- neither a lower nor an upper bound, while the user sizes
what survived by it. N is now counted in the file, by python-can's own reader here; a cut last
line is cut off, so every frame in a text log is whole.
"""

from __future__ import annotations

import json
import os
import subprocess
import xml.etree.ElementTree as ET
from pathlib import Path

import can
import pytest

from odocan.host.io.recording import stopped_after
from tests.limited import run_limited

ROOT = Path(__file__).resolve().parents[1]


def _run_limited(log: Path, limit_bytes: int, *more: str) -> subprocess.CompletedProcess[str]:
    return run_limited(["run", "--duration", "30", "--log", str(log), *more],
                       file_bytes=limit_bytes, cwd=ROOT,
                       env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=600)


@pytest.mark.parametrize("limit_bytes", [5000, 100_003])
@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_the_frames_said_are_the_frames_in_the_file(
    tmp_path: Path, suffix: str, limit_bytes: int
) -> None:
    log = tmp_path / f"drive{suffix}"
    done = _run_limited(log, limit_bytes)
    assert done.returncode == 2, done.stderr
    last = done.stderr.splitlines()[-1]
    assert last.startswith(f"error: --log {log}: File too large (recording stopped after "), last
    said = int(last.split("stopped after ")[1].split()[0])
    assert last.endswith(f"stopped after {said} frames)"), last
    read_back = list(can.LogReader(log))
    assert said == len(read_back) > 0
    if suffix != ".blf":
        assert log.read_bytes().endswith(b"\n")  # no cut line left


@pytest.mark.parametrize("suffix", [".log", ".blf"])
def test_the_report_of_a_stopped_recording_is_no_pass(tmp_path: Path, suffix: str) -> None:
    """``--report`` beside a ``--log`` a full disk stopped: the report said ``passed: true``
    and nothing of the log (the run exits 2); it records the recording's failure now, the
    frames the file holds, and is no pass. A ``.blf``'s header counted 0 objects (python-can's
    writer never finished it): it counts the frames read back now."""
    log, report = tmp_path / f"drive{suffix}", tmp_path / "r.json"
    done = _run_limited(log, 100_003, "--report", str(report))
    assert done.returncode == 2, done.stderr
    said = json.loads(report.read_text())
    assert said["passed"] is False
    read_back = list(can.LogReader(log))
    assert said["recording"] == {"path": str(log), "stopped_after_frames": len(read_back),
                                 "error": "File too large"}
    assert "PASS" in done.stdout  # the poses' verdict: the firmware is not to blame
    if suffix == ".blf":
        with can.BLFReader(log) as blf:
            assert blf.object_count == len(read_back) > 0
            assert blf.file_size == log.stat().st_size
        assert stopped_after(log, 0) == f"recording stopped after {len(read_back)} frames"


def test_a_recording_that_did_not_fail_is_not_in_the_report(tmp_path: Path) -> None:
    report = tmp_path / "r.json"
    done = _run_limited(tmp_path / "d.log", 10_000_000, "--report", str(report))
    assert done.returncode == 0, done.stderr
    said = json.loads(report.read_text())
    assert said["passed"] is True
    assert "recording" not in said


def test_the_junit_of_a_stopped_recording_fails(tmp_path: Path) -> None:
    """``--junit`` beside a ``--log`` a full disk stopped: the JUnit said 3 tests, 0 failures
    (a CI reading it saw a green run) where the JSON said ``passed: false`` and the run exited
    2; it carries the recording's failure now, a ``recording`` testcase with its figures."""
    log, junit = tmp_path / "drive.log", tmp_path / "j.xml"
    done = _run_limited(log, 100_003, "--junit", str(junit))
    assert done.returncode == 2, done.stderr
    suite = ET.parse(junit).getroot().find("testsuite")
    assert suite is not None
    assert suite.get("failures") == "1"
    failed = [case for case in suite.findall("testcase") if case.find("failure") is not None]
    assert [case.get("name") for case in failed] == ["recording"]
    failure = failed[0].find("failure")
    assert failure is not None
    frames = len(list(can.LogReader(log)))
    assert failure.get("message") == (f"--log {log}: File too large (recording stopped after "
                                      f"{frames} frames)")
    assert f"stopped_after_frames = {frames}" in (failure.text or "")
