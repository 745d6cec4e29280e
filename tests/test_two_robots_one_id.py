"""Two robots on one set of IDs, both from power-up (issue #11: "two sources on one ID are
reported"), and the judged floor (``host.judge.judgedfloor``).

An outside trial merged the candump logs of two kobukis started together: their UPTIME offsets
are one, so ``host.judge.sources`` saw one firmware; every encoder frame had a twin (the other
robot's, same COUNTER), every pose of the second firmware was refused as REPEATED and almost
every pose of the first was left out (it names a twinned frame), and ``analyze`` PASSed on the
one sample left ("within 0.1 mm", 0.000 m travelled) while the first firmware was 50 mm wrong.

The logs here are written directly (``tests/synth_log.py``): A drives one wandering drive, its
X ``BIAS_LSB`` off from encoder frame ``WRONG_FROM`` on; B (correct) another, both powered up at
t=0 on the same IDs, B's frames ``B_LATER_S`` after A's. The pose truth is
``tests/independent_checker.py`` on each robot's own log: A wrong, B right. Expected: the judges
name the two sources (``posestreams``, ``livestreams``) and never PASS.

The floor: a forger copying all but a few encoder frames (a twin for each, ``test_live_twins``'
``_with_twins``) leaves almost every pose out; a firmware 50 mm off there PASSed on the poses of
the first half second. Now UNJUDGED (``passed`` false, exit 1), with how many were judged.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import can
import pytest
from rich.console import Console

from odocan.host.cli.app import main
from odocan.host.io.logs import FrameCollector, read_log
from odocan.host.judge.analysis import Tolerance, analyze
from odocan.host.judge.livestreams import PAIR_WINDOW_S
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.judge.stream_analysis import analyze_file
from odocan.host.judge.stream_refusal import NotStreamable
from odocan.host.judge.watchend import end_watch
from odocan.host.judge.watchverdict import failures
from odocan.host.mqtt.endverdict import end_verdict
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.host.report.summary import print_summary
from odocan.sim.robot import load
from tests.independent_checker import check
from tests.synth_log import Synth, synthesize, wandering_drive
from tests.test_analysis_reboot import checker_robot
from tests.test_live_twins import _clean_run, _shifted_x, _with_twins

PMIR = load("pmir")
STEPS = 600  # 6 s
WRONG_FROM, BIAS_LSB = 100, 500  # A's X 50 mm off from 1 s on
B_LATER_S = 0.0004


def _robot(step_m: float, bias: bool) -> Synth:
    d_left, d_right = wandering_drive(PMIR, STEPS, step_m, seed=7)
    wrong = {k: BIAS_LSB for k in range(WRONG_FROM, STEPS + 1)} if bias else None
    return synthesize(PMIR, "exact", d_left, d_right, x_bias_100um=wrong)


def _later(line: str, by_s: float) -> str:
    t_s, rest = line.split(" ", 1)
    return f"({float(t_s.strip('()')) + by_s:.6f}) {rest}"


def _two_robots(tmp_path: Path, *, a_wrong: bool, later_s: float = B_LATER_S
                ) -> tuple[Path, Path, Path]:
    """(the merged log, A's own, B's own)."""
    a, b = _robot(0.004, a_wrong), _robot(0.003, False)  # B slower: their poses differ
    merged = a.lines() + [_later(line, later_s) for line in b.lines()]
    merged.sort(key=lambda line: float(line.split()[0].strip("()")))
    path = tmp_path / "two.log"
    path.write_text("".join(merged))
    return path, a.write(tmp_path / "a.log"), b.write(tmp_path / "b.log")


def _streamed(path: Path) -> dict[str, Any]:
    """``analyze_file``'s report, or the whole log's where the stream refuses (a twin before
    the cut: the CLI reads it whole then, ``stream_first.FirstPass.refuse``)."""
    try:
        return analyze_file(path, PMIR)
    except NotStreamable:
        return analyze(read_log(path), PMIR).report


def _truth(path: Path) -> bool:
    """The independent checker's verdict on one robot's own log (from power-up at 0, 0, 0)."""
    return check(path, checker_robot(PMIR), "exact", lambda _t: (0.0, 0.0, 0.0)).passed


@pytest.mark.parametrize("later_s", [B_LATER_S, 0.0, 0.005])
def test_two_robots_on_one_id_never_pass_and_are_named(tmp_path: Path, later_s: float) -> None:
    path, a_log, b_log = _two_robots(tmp_path, a_wrong=True, later_s=later_s)
    assert not _truth(a_log)  # A is 50 mm wrong from 1 s on
    assert _truth(b_log)
    for report in (analyze(read_log(path), PMIR).report, _streamed(path)):
        assert report["passed"] is False
        conflict = report["two_sources"]
        assert conflict["detail"].startswith("two sources on one ID: two ODOM_POSE_X streams")
        assert conflict["t_s"] < 0.1  # B's second pose frame
        assert conflict["frames_not_judged"] > 0.9 * len(path.read_text().splitlines())
        assert "two sources" in [e["kind"] for e in report["events"]]


def test_two_correct_robots_are_not_passed_either(tmp_path: Path,
                                                  capsys: pytest.CaptureFixture[str]) -> None:
    path, a_log, _ = _two_robots(tmp_path, a_wrong=False)
    assert _truth(a_log)
    for stream in ("never", "always"):
        assert main(["analyze", str(path), "--robot", "pmir", "--stream", stream]) == 1
        out = capsys.readouterr().out
        assert "FAIL: two sources on one ID: two ODOM_POSE_X streams interleave from t=" in out
        assert "frames from there not judged" in out


def test_one_robot_is_not_two(tmp_path: Path) -> None:
    """Each robot's own log: one source, judged as before (A FAILs for its pose, B PASSes)."""
    _, a_log, b_log = _two_robots(tmp_path, a_wrong=True)
    for path, right in ((a_log, False), (b_log, True)):
        report = analyze(read_log(path), PMIR).report
        assert "two_sources" not in report
        assert report["passed"] is right
        assert report["samples"]["judged_fraction"] == 1.0


def _arrays(messages: list[can.Message]) -> FrameCollector:
    frames = FrameCollector()
    for msg in messages:
        frames.on_message_received(msg)
    return frames


def test_a_verdict_on_a_few_poses_is_unjudged(tmp_path: Path,
                                              capsys: pytest.CaptureFixture[str]) -> None:
    clean = _clean_run()
    wrong = _shifted_x(clean, 1.5, BIAS_LSB)  # the firmware 50 mm off from 1.5 s on
    wrong_log = tmp_path / "wrong.log"
    _write(wrong, wrong_log)
    assert not check(wrong_log, checker_robot(PMIR), "exact", lambda _t: (0.0, 0.0, 0.0)).passed
    forged, twinned = _with_twins(wrong, 1, 3)  # a twin for every encoder frame after the 50th
    assert len(twinned) > 200
    report = analyze(_arrays(forged).arrays(), PMIR, "exact").report
    assert report["passed"] is False
    unjudged = report["judged_floor"]
    assert unjudged["judged_poses"] < 0.5 * unjudged["poses"]
    assert report["samples"]["judged_fraction"] == pytest.approx(
        unjudged["judged_poses"] / unjudged["poses"])
    out = io.StringIO()
    print_summary(report, Tolerance(), Console(file=out, width=300), title="t")
    assert f"UNJUDGED: only {unjudged['judged_poses']} of " in out.getvalue()
    path = tmp_path / "forged.log"
    _write(forged, path)
    for stream in ("never", "always"):
        code = main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                     "--stream", stream])
        assert code == 1
        assert "UNJUDGED: only" in capsys.readouterr().out


def test_a_few_twins_leave_the_verdict_judged() -> None:
    """The forger of ``test_live_twins`` (every 7th frame): 6 poses in 7 judged, PASS."""
    forged, _ = _with_twins(_clean_run(), 7, 3)
    result = analyze(_arrays(forged).arrays(), PMIR, "exact")
    assert result.passed
    assert "unjudged" not in result.report
    assert 0.8 < result.report["samples"]["judged_fraction"] < 0.9


def _write(messages: list[can.Message], path: Path) -> None:
    path.write_text("".join(
        f"({m.timestamp:.6f}) vcan0 {m.arbitration_id:03X}#{bytes(m.data).hex().upper()}\n"
        for m in messages))


def test_a_second_robot_powered_up_later_is_cut_alike_whole_and_streamed(tmp_path: Path) -> None:
    """B powered up 1 s after A (UPTIME offsets 1 s apart: within ``UPTIME_MATCH_S``, which
    ``sources`` cannot tell from a reboot): both correct, named from B's first poses (or A's
    frame B's first pairs with), the frames before judged alike by both paths (the stream cuts
    its lives there too)."""
    a = _robot(0.004, False)
    d_left, d_right = wandering_drive(PMIR, STEPS - 100, 0.003, seed=7)
    b = synthesize(PMIR, "exact", d_left, d_right, t0_s=1.0)
    merged = sorted(a.lines() + b.lines(), key=lambda line: float(line.split()[0].strip("()")))
    path = tmp_path / "late.log"
    path.write_text("".join(merged))
    assert _truth(a.write(tmp_path / "a.log"))
    whole, streamed = analyze(read_log(path), PMIR).report, analyze_file(path, PMIR)
    for report in (whole, streamed):
        assert report["passed"] is False
        # from the earlier frame of B's first pair: A's same COUNTER, at most PAIR_WINDOW_S before
        assert 1.0 - PAIR_WINDOW_S <= report["two_sources"]["t_s"] <= 1.0
        assert report["onboard_vs_reference"]["max_position_error_m"] <= 1e-4
    assert streamed["two_sources"] == whole["two_sources"]
    assert streamed["samples"] == whole["samples"]


def test_the_live_judges_name_the_two_robots(tmp_path: Path) -> None:
    """The monitor and the bridge fed the merged log (A 50 mm wrong): CONFLICT once a window of
    pose frames tells it, never OK after, no POSE WRONG blamed on either, the end verdicts FAIL
    naming the two sources."""
    path, _, _ = _two_robots(tmp_path, a_wrong=True)
    monitor = BusMonitor(PMIR, "exact")
    bridge = RobotTelemetry("r", Geometry.of(PMIR), "exact", counter_bits=PMIR.counter_bits)
    states: list[tuple[float, str]] = []
    for msg in can.LogReader(str(path)):
        monitor.feed(msg, now_s=msg.timestamp)
        bridge.feed(msg)
        states.append((msg.timestamp, monitor.health(msg.timestamp)["state"]))
    told_s = next(t for t, state in states if state == "CONFLICT")
    assert told_s < 1.0  # 32 pose periods with a pair (of 48) after B's first
    assert not {state for t, state in states if t >= told_s} & {"OK", "POSE WRONG"}
    end_watch(monitor.tracker, monitor.distance)
    fails = failures(monitor.tracker, monitor.distance, monitor.twist, monitor.sources)
    assert fails
    assert fails[0].startswith("two sources on one ID: two ODOM_POSE_X streams")
    assert monitor.tracker.wrongs.count == 0
    assert monitor.sources.conflict_from_s is not None
    assert monitor.sources.conflict_from_s < 0.1
    whole = analyze(read_log(path), PMIR).report["two_sources"]  # the same rule, vectorised
    assert monitor.sources.conflict_from_s == pytest.approx(whole["t_s"], abs=1e-9)
    bridge.end_watch()
    verdict = end_verdict(bridge)
    assert verdict.verdict == "FAIL"
    assert "two sources on one ID" in verdict.reason
    assert "two sources" in [e["kind"] for e in bridge.events]


def test_replay_does_not_judge_two_robots(tmp_path: Path,
                                          capsys: pytest.CaptureFixture[str]) -> None:
    """``odocan replay`` of two robots merged: the replayed firmware cannot be compared with the
    log's poses (whose are they?), UNJUDGED, exit 1, naming the two sources; each robot's own
    log still replays to a PASS. Real runs (``odocan run``: the replay needs MOTOR_CMD)."""
    a_log, b_log = _run(tmp_path / "a.log", 1), _run(tmp_path / "b.log", 2)
    merged = tmp_path / "two.log"
    lines = a_log.read_text().splitlines(keepends=True) + \
        b_log.read_text().splitlines(keepends=True)
    lines.sort(key=lambda line: float(line.split()[0].strip("()")))
    merged.write_text("".join(lines))
    assert main(["replay", str(a_log), "--robot", "kobuki"]) == 0
    capsys.readouterr()
    assert main(["replay", str(merged), "--robot", "kobuki"]) == 1
    assert "UNJUDGED: two sources on one ID: two ODOM_POSE_X streams" in capsys.readouterr().out


def _run(path: Path, seed: int) -> Path:
    assert main(["run", "--robot", "kobuki", "--duration", "2", "--seed", str(seed),
                 "--log", str(path)]) == 0
    return path
