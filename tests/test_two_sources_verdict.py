"""Two firmwares on one node ID (issue #11): ``analyze`` (whole and streamed) and the monitor name
them in the verdict instead of blaming a pose.

The log is written directly (``tests/synth_log.py``): firmware A drives the whole log; firmware B,
powered up at encoder frame ``SECOND_AT`` (3 s) on the same bus, sends its own frames (pose from
0, E2E counters and UPTIME from 0) until frame ``KILLED_AT`` (6 s), interleaved with A's. Both
are correct firmwares. Their pose frames cannot be told apart, so from B's first frame no pose
can be judged: the verdict is the FAIL "two firmwares answered on one node ID from t=... s", the
pose before it is judged as usual (against ``tests/independent_checker.py`` on the frames before
that time, and a firmware wrong before it still fails for its pose). The time expected is B's
first summary, found here by decoding the log with cantools.
"""

from __future__ import annotations

import io
from pathlib import Path

import can
import pytest
from rich.console import Console

from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import POSITION_LSB_M, Tolerance, analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.stream_analysis import analyze_file
from odocan.host.report.summary import print_summary
from odocan.sim.contract import database
from odocan.sim.robot import load
from tests.independent_checker import check
from tests.synth_log import Synth, synthesize, wandering_drive
from tests.test_analysis_reboot import checker_robot

PMIR = load("pmir")
DB = database()
FIRMWARE_IDS = {m.frame_id for m in DB.messages if "ODOM_MCU" in m.senders}
STEPS = 900  # 9 s
SECOND_AT, KILLED_AT = 300, 600  # B's first and last encoder frame
B_LATER_S = 0.0004  # B's frames come 0.4 ms after A's of the same tick


def _frames(synth: Synth, start: int, stop: int | None, *, firmware: bool) -> list[str]:
    """Lines of ``synth``'s encoder frames [start, stop): its firmware's or the others."""
    return [line for line in synth.lines(start, stop)
            if (int(line.split()[2].split("#")[0], 16) in FIRMWARE_IDS) == firmware]


def _later(line: str) -> str:
    t_s, rest = line.split(" ", 1)
    return f"({float(t_s.strip('()')) + B_LATER_S:.6f}) {rest}"


def two_firmwares(tmp_path: Path, bias: dict[int, int] | None = None) -> Path:
    """The log (module docstring); ``bias``: firmware A's X off by that many LSB at those
    encoder frames."""
    d_left, d_right = wandering_drive(PMIR, STEPS, 0.004, seed=7)
    a = synthesize(PMIR, "exact", d_left, d_right, x_bias_100um=bias)
    b = synthesize(PMIR, "exact", d_left, d_right, reboot_at=SECOND_AT)
    lines = a.lines(0, SECOND_AT) + a.lines(KILLED_AT)
    lines += a.lines(SECOND_AT, KILLED_AT)
    lines += [_later(line) for line in _frames(b, SECOND_AT, KILLED_AT, firmware=True)]
    lines.sort(key=lambda line: float(line.split()[0].strip("()")))
    path = tmp_path / "two.log"
    path.write_text("".join(lines))
    return path


def first_summary_of_b(path: Path) -> float:
    """Bus time of B's first ODOM_STATUS summary (cantools): UPTIME 0 after A's went past 0."""
    status = DB.get_message_by_name("ODOM_STATUS")
    seen_a_running = False
    for line in path.read_text().splitlines():
        t_s, _, frame = line.split()
        can_id, data = frame.split("#")
        if int(can_id, 16) != status.frame_id:
            continue
        s = status.decode(bytes.fromhex(data), decode_choices=True)
        assert isinstance(s, dict)
        if str(s["PAGE"]) != "SUMMARY":
            continue
        if int(str(s["UPTIME"])) > 0:
            seen_a_running = True
        elif seen_a_running:
            return float(t_s.strip("()"))
    raise AssertionError("no second firmware in the log")


def _before(path: Path, t_s: float, into: Path) -> Path:
    into.write_text("".join(line + "\n" for line in path.read_text().splitlines()
                            if float(line.split()[0].strip("()")) < t_s))
    return into


def test_two_firmwares_fail_by_name_and_the_pose_there_is_not_judged(tmp_path: Path) -> None:
    path = two_firmwares(tmp_path)
    t_b = first_summary_of_b(path)
    assert 2.9 < t_b < 3.1
    verdict = check(_before(path, t_b, tmp_path / "before.log"), checker_robot(PMIR), "exact",
                    lambda t: (0.0, 0.0, 0.0))
    assert verdict.samples > 100
    assert verdict.passed  # A alone, up to B: right
    for report in (analyze(read_log(path), PMIR).report, analyze_file(path, PMIR)):
        assert report["passed"] is False
        conflict = report["two_sources"]
        assert conflict["t_s"] == pytest.approx(t_b, abs=1e-6)
        assert conflict["detail"] == (f"two firmwares answered on one node ID from t={t_b:.3f} "
                                      "s: the pose cannot be judged")
        assert report["onboard_vs_reference"]["max_position_error_m"] <= POSITION_LSB_M
        assert [e["kind"] for e in report["events"]] == ["two sources"]  # not a reboot
    out = io.StringIO()
    print_summary(analyze(read_log(path), PMIR).report, Tolerance(), Console(file=out, width=200),
                  title="t")
    assert f"FAIL: two firmwares answered on one node ID from t={t_b:.3f} s" in out.getvalue()


def test_a_wrong_pose_before_the_second_firmware_still_fails_for_it(tmp_path: Path) -> None:
    path = two_firmwares(tmp_path, bias={100: 30})  # 3 mm off at 1 s
    report = analyze(read_log(path), PMIR).report
    assert report["passed"] is False
    assert report["two_sources"]
    assert report["onboard_vs_reference"]["max_position_error_m"] > 2.5e-3


def test_the_cli_names_the_two_firmwares(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = two_firmwares(tmp_path)
    t_b = first_summary_of_b(path)
    for stream in ("never", "always"):
        assert main(["analyze", str(path), "--stream", stream]) == 1
        out = capsys.readouterr().out
        assert f"FAIL: two firmwares answered on one node ID from t={t_b:.3f} s" in out
        assert "reboot" not in out


def test_the_monitor_names_the_two_firmwares(tmp_path: Path) -> None:
    """The live judge fed the same log: CONFLICT while both answer, then no pose judged (never
    POSE WRONG or OK), no pose latched wrong from B's first summary on, and the reason."""
    path = two_firmwares(tmp_path)
    t_b = first_summary_of_b(path)
    monitor = BusMonitor(PMIR, "exact")
    verdicts = set()
    for msg in can.LogReader(str(path)):
        monitor.feed(msg, now_s=msg.timestamp)
        if msg.timestamp > t_b + 0.5:  # B heard twice: CONFLICT, then no pose judged
            verdicts.add(monitor.health(msg.timestamp)["state"])
    assert verdicts == {"CONFLICT", "UNVERIFIED"}
    assert monitor.health(msg.timestamp)["why"] == [monitor.sources.conflict_text()]
    monitor.tracker.wrongs.finish(monitor.tracker.allowance_m)
    assert monitor.sources.conflict_from_s == pytest.approx(t_b, abs=1e-6)
    assert monitor.tracker.wrongs.count == 0
    assert monitor.sources.conflict_text() == (
        f"two firmwares answered on one node ID from t={t_b:.3f} s: the pose cannot be judged")

