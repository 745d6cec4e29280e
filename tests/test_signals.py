"""SIGTERM is handled as SIGINT: the run stops, checks what ran, and every log is finished.

``python -m odocan run --duration 3600 --log X`` is started as a subprocess, killed with SIGTERM
once its log has content, and the log read back with python-can's own readers: every frame is
readable, an ``.asc`` ends with its footer, a ``.blf`` header counts exactly the objects that
follow. The summary is on stdout, its verdict line says the run was STOPPED (never a plain PASS:
a CI job killed by its timeout must not read a pass) and the exit code is 143, 128 + SIGTERM.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from xml.etree import ElementTree

import can
import pytest

ROOT = Path(__file__).resolve().parents[1]
START_TIMEOUT_S = 60.0
EXIT_TIMEOUT_S = 60.0


def _start(*argv: str) -> subprocess.Popen[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.Popen(
        [sys.executable, "-m", "odocan", *argv],
        cwd=ROOT,
        env=env,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _wait_for_content(proc: subprocess.Popen[str], path: Path, min_bytes: int) -> None:
    deadline = time.monotonic() + START_TIMEOUT_S
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            pytest.fail(f"odocan ended early ({proc.returncode}): {proc.communicate()}")
        if path.exists() and path.stat().st_size >= min_bytes:
            return
        time.sleep(0.05)
    proc.kill()
    pytest.fail(f"{path} stayed under {min_bytes} bytes for {START_TIMEOUT_S} s")


def _terminate(proc: subprocess.Popen[str]) -> tuple[int, str, str]:
    proc.send_signal(signal.SIGTERM)
    try:
        out, err = proc.communicate(timeout=EXIT_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, err = proc.communicate()
        pytest.fail(f"no exit {EXIT_TIMEOUT_S} s after SIGTERM: {err}")
    return proc.returncode, out, err


def _simulated_s(err: str) -> float:
    line = next(x for x in err.splitlines() if x.startswith("interrupted after"))
    return float(line.split()[2])


@pytest.mark.parametrize("suffix", [".log", ".asc", ".blf"])
def test_sigterm_finishes_the_run_and_its_log(tmp_path: Path, suffix: str) -> None:
    log = tmp_path / f"drive{suffix}"
    report = tmp_path / "report.json"
    proc = _start("run", "--duration", "3600", "--log", str(log), "--report", str(report))
    _wait_for_content(proc, log, 200_000)
    code, out, err = _terminate(proc)

    assert code == 143, err
    assert "Traceback" not in err
    simulated_s = _simulated_s(err)
    assert 0 < simulated_s < 3600
    verdict = out.rstrip().splitlines()[-1]
    assert verdict.startswith(
        f"STOPPED by SIGTERM at {simulated_s:g} s of 3600 s: partial drive PASS: "), verdict
    assert "WHEEL_ENCODERS" in out
    assert report.is_file()
    saved = json.loads(report.read_text())
    # not what was asked: never a pass to a CI step reading .passed (as the fleet's report);
    # the partial drive's pose passed: the firmware is not blamed
    assert saved["passed"] is False
    assert saved["stopped"] == {"signal": "SIGTERM", "done": simulated_s, "asked": 3600.0,
                                "unit": "s", "partial_passed": True}

    frames = list(can.LogReader(log))
    # 10 ms encoder frames: the log holds the whole interrupted run, up to the last tick
    encoders = [m for m in frames if m.arbitration_id == 0x100]
    assert abs(len(encoders) - simulated_s * 100) <= 1, (len(encoders), simulated_s)
    assert abs(frames[-1].timestamp - simulated_s) < 0.02
    if suffix == ".asc":
        assert log.read_text().rstrip().endswith("End TriggerBlock")
    if suffix == ".blf":
        reader = can.BLFReader(log)
        count = sum(1 for _ in reader)
        # python-can counts one object per frame plus none for the container blocks it reads
        assert reader.object_count == count == len(frames)
        assert reader.file_size == log.stat().st_size


def test_sigint_stops_the_run_with_130_and_a_failed_completed_testcase(tmp_path: Path) -> None:
    """Ctrl-C as SIGTERM, with its own code; the JUnit page says the run did not complete
    (its pose checks still pass: the firmware is not blamed)."""
    log, junit = tmp_path / "drive.log", tmp_path / "junit.xml"
    proc = _start("run", "--duration", "3600", "--log", str(log), "--junit", str(junit))
    _wait_for_content(proc, log, 200_000)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=EXIT_TIMEOUT_S)
    assert proc.returncode == 130, err
    simulated_s = _simulated_s(err)
    assert f"STOPPED by SIGINT at {simulated_s:g} s of 3600 s: partial drive PASS" in out
    cases = {c.get("name"): c for c in ElementTree.parse(junit).getroot().iter("testcase")}
    assert cases["completed"].find("failure") is not None
    assert cases["onboard_vs_reference_position"].find("failure") is None


def test_sigterm_without_a_handler_would_leave_the_blf_header_empty(tmp_path: Path) -> None:
    """The control: SIGKILL (no handler can run) leaves the header at 0 objects, which is what
    the test above proves does not happen on SIGTERM."""
    log = tmp_path / "killed.blf"
    proc = _start("run", "--duration", "3600", "--log", str(log))
    _wait_for_content(proc, log, 200_000)
    proc.kill()
    proc.communicate(timeout=EXIT_TIMEOUT_S)
    assert can.BLFReader(log).object_count == 0


def _udp_listener(group: str) -> can.BusABC:
    import argparse

    from odocan.host.io.buses import open_bus

    args = argparse.Namespace(interface="udp_multicast", channel=group, bitrate=None,
                              bus_arg=["hop_limit=0"], faults="")
    try:
        return open_bus(args)
    except Exception as exc:
        pytest.skip(f"udp_multicast unavailable: {exc}")


def test_sigterm_stops_replay_realtime_cleanly(tmp_path: Path) -> None:
    import secrets

    from odocan.host.cli.app import main

    log = tmp_path / "drive.log"
    assert main(["run", "--duration", "30", "--log", str(log)]) == 0
    group = f"239.255.{secrets.randbelow(250) + 1}.{secrets.randbelow(250) + 1}"
    listener = _udp_listener(group)
    try:
        proc = _start("replay", str(log), "--realtime", "-i", "udp_multicast", "-c", group,
                      "--bus-arg", "hop_limit=0")
        for _ in range(20):  # well under way: the 30 s log holds 10 800 frames
            if listener.recv(START_TIMEOUT_S) is None:
                proc.kill()
                pytest.skip("udp_multicast does not loop back on this machine")
        code, out, err = _terminate(proc)
    finally:
        listener.shutdown()
    assert (code, err) == (143, ""), err  # it did not play what it was asked
    assert out.startswith("replay: interrupted, "), out
    played, total = (int(w) for w in out.split()[2:5:2])
    assert 0 < played < total, out


def _catches_sigterm(pid: int) -> bool:
    status = Path(f"/proc/{pid}/status").read_text()
    caught = int(next(x for x in status.splitlines() if x.startswith("SigCgt:")).split()[1], 16)
    return bool(caught & (1 << (signal.SIGTERM - 1)))


def test_sigterm_ends_monitor_with_its_json(tmp_path: Path) -> None:
    import json

    log = tmp_path / "heard.log"  # made once the monitor is past its imports and options
    proc = _start("monitor", "-i", "virtual", "-c", f"sig-{os.getpid()}", "--json",
                  "--log", str(log))
    deadline = time.monotonic() + START_TIMEOUT_S
    while not (_catches_sigterm(proc.pid) and log.exists()):
        if time.monotonic() > deadline or proc.poll() is not None:
            proc.kill()
            pytest.fail(f"monitor never handled SIGTERM: {proc.communicate()}")
        time.sleep(0.05)
    time.sleep(0.2)  # a signal before its receive loop stops it the same way (JSON, exit 0)
    code, out, err = _terminate(proc)
    assert (code, err) == (0, "")
    assert isinstance(json.loads(out), dict)


def test_sigterm_ends_a_fleet_with_its_report(tmp_path: Path) -> None:
    """``odocan fleet`` stopped by SIGTERM mid-run still prints its summary and its report, says
    it stopped, and exits 143 (a CI job's timeout must not read a fleet run as passed)."""
    import json

    report = tmp_path / "fleet.json"
    proc = _start("fleet", "-n", "2", "--duration", "600", "--report", str(report))
    assert proc.stderr is not None
    deadline = time.monotonic() + START_TIMEOUT_S
    said = [proc.stderr.readline()]  # the start line: the clock is running
    while not said[-1].startswith("fleet: ") and time.monotonic() < deadline and said[-1]:
        said.append(proc.stderr.readline())
    assert "robots running" in said[-1], (proc.poll(), said)
    code, out, err = _terminate(proc)
    assert code == 143, err  # stopped before its 600 s: never 0, whatever the partial verdict
    assert out.startswith("fleet: 2 robots, "), out
    assert "STOPPED by SIGTERM at " in out, out
    assert " s of 600 s: partial run " in out, out
    assert "Traceback" not in err
    written = json.loads(report.read_text())
    assert written["robots"] == 2
    assert written["stopped"]["signal"] == "SIGTERM"
    assert 0 < written["stopped"]["done"] < 600
