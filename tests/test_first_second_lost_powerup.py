"""A reset in the firmware's first second of uptime whose new power-up pose pair the bus lost
(issue #11: a FAIL must never blame a correct firmware).

The case (lockstep rig, pmir on the circle, ``FaultRig``): ``board.reboot()`` at tick 10, 30 or
60, and the bus loses the new firmware's first ODOM_POSE_X and ODOM_POSE_Y (its poses of E2E
COUNTER 0). The power-up tick's signature (``host.judge.bootticks``) needed that pose, or a
later pose of COUNTER 0 after the summary; without it no judge told the reboot and the correct
firmware FAILed everywhere against the old life's reference: measured before the fix, 9.4 mm
(tick 10), 84 mm (tick 30), 0.23 m (tick 60) in analyze (whole and streamed), the monitor and
the bridge. What else the reset leaves: its boot summary (UPTIME 0, COUNTER 0) breaks the
ODOM_STATUS sequence, the first pose heard after it restarts its COUNTER small (1, 2) sooner
than one life could count on to it, and the next summary continues the boot summary's
(``bootticks.restarts_small``). A reset at tick 150 (after the pose's first lap) is the control.

Each judge's verdict is checked against ``tests/independent_checker.py`` (float64 odometry on
cantools-decoded frames, told the frame the new firmware primed on by the test's own look at
the frames before the loss), never against host code. Wrong firmwares (1, 3 LSB and 1 m off in X
from the new power-up) FAIL every judge.
"""

from __future__ import annotations

import functools
import json
from pathlib import Path

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import POSITION_LSB_M, analyze
from odocan.host.judge.stream_analysis import analyze_file
from odocan.host.mqtt.endverdict import end_verdict
from odocan.sim.board import TICK_S
from odocan.sim.scenarios import Phase, PhaseScenario, get_scenario
from tests import independent_checker as ic
from tests.fault_rig import FaultRig
from tests.test_first_second_reboot import (
    PMIR,
    POSE_IDS,
    _decoded,
    _live,
    _reencoded,
    _robot,
    _written,
)

RUN_S = 3.0


@functools.cache
def _drive(reboot_at: int, firmware: str = "python") -> tuple[can.Message, ...]:
    """The rig's frames: pmir on the circle, its MCU reset before tick ``reboot_at``."""
    heard: list[can.Message] = []
    scenario = get_scenario("circle", PMIR, duration_s=60.0)
    with FaultRig(scenario=scenario, firmware=firmware) as rig:
        rig.observers.append(lambda _k, got: heard.extend(got))
        rig.before_board.append(lambda k: rig.board.reboot() if k == reboot_at else None)
        rig.run(RUN_S)
    return tuple(heard)


def _primed_t(messages: tuple[can.Message, ...], reboot_at: int) -> float:
    """cantools, on the frames before the loss: the new firmware's first ODOM_POSE_X reads X 0
    at COUNTER 0; the bus time of the encoder frame it primed on (the latest before it)."""
    first = next(m for m in messages if m.arbitration_id == fr.ODOM_POSE_X_ID
                 and m.timestamp >= reboot_at * TICK_S)
    assert (_decoded(first)["X"], _decoded(first)["COUNTER"]) == (0, 0)
    return max(m.timestamp for m in messages if m.arbitration_id == fr.WHEEL_ENCODERS_ID
               and m.timestamp <= first.timestamp)


def _lost(messages: tuple[can.Message, ...], reboot_at: int, pairs: int,
          bias_lsb: int) -> tuple[can.Message, ...]:
    """The bus loses the new firmware's first ``pairs`` pose pairs; its X ``bias_lsb`` off
    from then (E2E re-protected with the frame's own COUNTER: a wrong firmware)."""
    out, seen = [], dict.fromkeys(POSE_IDS, 0)
    for m in messages:
        if m.arbitration_id in POSE_IDS and m.timestamp >= reboot_at * TICK_S:
            seen[m.arbitration_id] += 1
            if seen[m.arbitration_id] <= pairs:
                continue
            if bias_lsb and m.arbitration_id == fr.ODOM_POSE_X_ID:
                signals = _decoded(m)
                signals["X"] += bias_lsb
                m = _reencoded(m, signals, fr.ODOM_POSE_X_DATA_IDS)
        out.append(m)
    return tuple(out)


def _every_judge(messages: tuple[can.Message, ...], path: Path, primed_t: float
                 ) -> tuple[ic.Verdict, dict[str, tuple[str, float]]]:
    """The checker's verdict and each judge's (verdict, worst position error m)."""
    own = ic.check(_written(messages, path), _robot(), "exact", lambda _t: (0.0, 0.0, 0.0),
                   reboots_t_s=[primed_t])
    whole = analyze(read_log(path), PMIR, "exact").report
    streamed = analyze_file(path, PMIR, "exact", chunk_frames=97)
    assert json.dumps(streamed) == json.dumps(whole)
    assert [r["reference_start"] for r in whole["reboots"]] == ["power-up"]
    monitor, bridge = _live(messages)
    assert [e["kind"] for e in monitor.events if e["kind"] == "reboot"] == ["reboot"]
    assert bridge.reboots == 1
    bridge.end_watch()
    worst = whole["onboard_vs_reference"]["max_position_error_m"]
    return own, {
        "analyze": ("PASS" if whole["passed"] else "FAIL", worst),
        "monitor": (monitor.health(messages[-1].timestamp)["state"],
                    monitor.tracker.vs_reference.max_dpos_m),
        "bridge": (end_verdict(bridge).verdict, bridge.tracker.vs_reference.max_dpos_m),
    }


@pytest.mark.parametrize("pairs", [1, 2])
@pytest.mark.parametrize("reboot_at", [10, 30, 60, 150])
def test_a_first_second_reset_whose_power_up_pose_is_lost_passes_the_correct_firmware(
    reboot_at: int, pairs: int, tmp_path: Path
) -> None:
    """Before: no judge told the reset; FAIL by 9.4 mm, 84 mm, 0.23 m (ticks 10, 30, 60)."""
    messages = _drive(reboot_at)
    own, judges = _every_judge(_lost(messages, reboot_at, pairs, 0), tmp_path / "right.log",
                               _primed_t(messages, reboot_at))
    assert own.samples > 100
    assert own.passed
    assert judges["analyze"][0] == "PASS"
    assert judges["monitor"][0] == "OK"
    assert judges["bridge"][0] == "PASS"
    for name, (_, error_m) in judges.items():
        assert error_m == pytest.approx(own.max_position_error_m, abs=0.1 * POSITION_LSB_M), name


@pytest.mark.parametrize("bias_lsb", [1, 3, 10_000])
@pytest.mark.parametrize("reboot_at", [10, 30, 60])
def test_a_wrong_firmware_after_such_a_reset_fails_every_judge(
    reboot_at: int, bias_lsb: int, tmp_path: Path
) -> None:
    """1 LSB .. 1 m off from the new power-up: FAIL everywhere, never PASS nor OK (at tick 10
    the live judges once took the silence of the poses the E2E check refused for a stall and
    placed the position at the wrong pose: a 1 LSB firmware PASSed the bridge)."""
    messages = _drive(reboot_at)
    own, judges = _every_judge(_lost(messages, reboot_at, 1, bias_lsb), tmp_path / "wrong.log",
                               _primed_t(messages, reboot_at))
    assert not own.passed
    assert judges["analyze"][0] == "FAIL"
    assert judges["monitor"][0] == "POSE WRONG"
    assert judges["bridge"][0] == "FAIL"
    for name, (_, error_m) in judges.items():
        assert error_m == pytest.approx(own.max_position_error_m, abs=0.1 * POSITION_LSB_M), name


def test_the_c_firmware_passes_too(tmp_path: Path) -> None:
    """The C port's frames, the same reset at tick 30 and the same loss."""
    messages = _drive(30, "c")
    own, judges = _every_judge(_lost(messages, 30, 1, 0), tmp_path / "c.log",
                               _primed_t(messages, 30))
    assert own.passed
    assert [v for v, _ in judges.values()] == ["PASS", "OK", "PASS"]


@pytest.mark.parametrize("reboot_at", [32, 64, 96])
def test_a_reset_after_the_old_poses_counter_15_passes_the_correct_firmware(
    reboot_at: int, tmp_path: Path
) -> None:
    """A reset 32 k ticks in (the old pose's last COUNTER 15): the new COUNTER 1, 40 ms after
    it, is what one life sends two frames on, so of the COUNTERs only ODOM_STATUS's breaks; the
    twist's DISTANCE going back tells it (``host.judge.distfall``). Before: FAIL by 93 mm
    (tick 32), 0.25 m (64), 0.41 m (96) in every judge."""
    messages = _drive(reboot_at)
    own, judges = _every_judge(_lost(messages, reboot_at, 1, 0), tmp_path / "lap.log",
                               _primed_t(messages, reboot_at))
    assert own.samples > 100
    assert own.passed
    assert [v for v, _ in judges.values()] == ["PASS", "OK", "PASS"]
    for name, (_, error_m) in judges.items():
        assert error_m == pytest.approx(own.max_position_error_m, abs=0.1 * POSITION_LSB_M), name


@pytest.mark.parametrize("bias_lsb", [1, 3, 10_000])
@pytest.mark.parametrize("reboot_at", [32, 64, 96])
def test_a_wrong_firmware_after_a_reset_at_counter_15_fails_every_judge(
    reboot_at: int, bias_lsb: int, tmp_path: Path
) -> None:
    """1 LSB .. 1 m off from the new power-up, the reset told by DISTANCE: FAIL everywhere."""
    messages = _drive(reboot_at)
    own, judges = _every_judge(_lost(messages, reboot_at, 1, bias_lsb), tmp_path / "wrong.log",
                               _primed_t(messages, reboot_at))
    assert not own.passed
    assert [v for v, _ in judges.values()] == ["FAIL", "POSE WRONG", "FAIL"]
    for name, (_, error_m) in judges.items():
        assert error_m == pytest.approx(own.max_position_error_m, abs=0.1 * POSITION_LSB_M), name


def test_the_c_firmware_passes_a_reset_at_counter_15_too(tmp_path: Path) -> None:
    """The C port's frames, a reset at tick 64 and the same loss."""
    messages = _drive(64, "c")
    own, judges = _every_judge(_lost(messages, 64, 1, 0), tmp_path / "c64.log",
                               _primed_t(messages, 64))
    assert own.passed
    assert [v for v, _ in judges.values()] == ["PASS", "OK", "PASS"]


def _twists_lost(messages: tuple[can.Message, ...], reboot_at: int, twists: int
                 ) -> tuple[can.Message, ...]:
    """The bus loses the new firmware's first ``twists`` ODOM_TWIST frames as well."""
    out, seen = [], 0
    for m in messages:
        if m.arbitration_id == fr.ODOM_TWIST_ID and m.timestamp >= reboot_at * TICK_S:
            seen += 1
            if seen <= twists:
                continue
        out.append(m)
    return tuple(out)


@pytest.mark.parametrize("twists", [1, 2, 3])
@pytest.mark.parametrize("reboot_at", [32, 64])
def test_its_first_twists_lost_too_the_next_twists_distance_tells_it(
    reboot_at: int, twists: int, tmp_path: Path
) -> None:
    """The new firmware's first 1..3 twists lost as well: the first twist heard (COUNTER 1..3,
    less than 80 ms after the boot summary) still reads DISTANCE below the old life's last
    (the live judges read it at the next summary). Before the window reached past the first
    pose: the monitor and the bridge FAILed the correct firmware with 1 twist lost, all four
    judges with 2 or 3."""
    messages = _drive(reboot_at)
    lost = _twists_lost(_lost(messages, reboot_at, 1, 0), reboot_at, twists)
    own, judges = _every_judge(lost, tmp_path / "twists.log", _primed_t(messages, reboot_at))
    assert own.passed
    assert [v for v, _ in judges.values()] == ["PASS", "OK", "PASS"]


@pytest.mark.parametrize("twists", [4, 5])
@pytest.mark.parametrize("reboot_at", [32, 64])
def test_its_first_four_or_five_twists_lost_too_the_twist_before_the_next_summary_tells_it(
    reboot_at: int, twists: int, tmp_path: Path
) -> None:
    """The new firmware's first 4 (5) twists lost as well: the first twist heard has COUNTER 4
    (5), 80 (100) ms after the boot summary, past the window; its DISTANCE below the old
    life's last still ties to the summary, heard by the next one and no more twists counted
    than the time since allows (``bootticks.tied_to_boot``). Before: FAIL by 93 mm (tick 32)
    in every judge, the checker PASSing; with the reboot told, the streamed analyze left the
    new life's first twist in where the whole one left it out (``DistanceJudge.talked_before``)."""
    messages = _drive(reboot_at)
    lost = _twists_lost(_lost(messages, reboot_at, 1, 0), reboot_at, twists)
    own, judges = _every_judge(lost, tmp_path / "four.log", _primed_t(messages, reboot_at))
    assert own.samples > 100
    assert own.passed
    assert [v for v, _ in judges.values()] == ["PASS", "OK", "PASS"]
    for name, (_, error_m) in judges.items():
        assert error_m == pytest.approx(own.max_position_error_m, abs=0.1 * POSITION_LSB_M), name


@pytest.mark.parametrize("bias_lsb", [100, 10_000])
def test_a_pose_10_mm_or_1_m_off_after_that_reset_fails_every_judge(
    bias_lsb: int, tmp_path: Path
) -> None:
    """The same drive, 4 twists lost, X 10 mm (1 m) off from the new power-up (E2E re-protected:
    a wrong firmware): the reboot told, FAIL everywhere by what the checker finds."""
    messages = _drive(32)
    lost = _twists_lost(_lost(messages, 32, 1, bias_lsb), 32, 4)
    own, judges = _every_judge(lost, tmp_path / "wrong.log", _primed_t(messages, 32))
    assert not own.passed
    assert own.max_position_error_m > 0.9 * bias_lsb * POSITION_LSB_M
    assert [v for v, _ in judges.values()] == ["FAIL", "POSE WRONG", "FAIL"]
    for name, (_, error_m) in judges.items():
        assert error_m == pytest.approx(own.max_position_error_m, abs=0.1 * POSITION_LSB_M), name


@functools.cache
def _drive_still(reboot_at: int) -> tuple[can.Message, ...]:
    """The rig's frames: pmir standing its first second (reset before tick ``reboot_at``),
    then driving an arc."""
    heard: list[can.Message] = []
    scenario = PhaseScenario("still", [Phase(1.0, 0.0, 0.0), Phase(2.0, 0.4, 0.6)])
    with FaultRig(scenario=scenario, firmware="python") as rig:
        rig.observers.append(lambda _k, got: heard.extend(got))
        rig.before_board.append(lambda k: rig.board.reboot() if k == reboot_at else None)
        rig.run(RUN_S)
    return tuple(heard)


@pytest.mark.parametrize("bias_lsb", [0, 100, 10_000])
@pytest.mark.parametrize("reboot_at", [32, 64])
def test_a_robot_standing_at_such_a_reset_is_judged_right(
    reboot_at: int, bias_lsb: int, tmp_path: Path
) -> None:
    """Standing still since power-up (DISTANCE 0 in both lives: no fall), the first pose pair
    and 4 twists lost: NAV_STATUS's COUNTER restarting tells the reboot in every judge
    (``host.judge.navrestart``; before it, none told it), and the verdict is the same either way:
    the robot had not moved, so the old life's reference is the new one's (the checker with and
    without the reboot agree). Measured: the correct firmware PASSes, 10 mm and 1 m off FAIL,
    in every judge."""
    messages = _drive_still(reboot_at)
    lost = _twists_lost(_lost(messages, reboot_at, 1, bias_lsb), reboot_at, 4)
    path = _written(lost, tmp_path / "still.log")
    told = ic.check(path, _robot(), "exact", lambda _t: (0.0, 0.0, 0.0),
                    reboots_t_s=[_primed_t(messages, reboot_at)])
    untold = ic.check(path, _robot(), "exact", lambda _t: (0.0, 0.0, 0.0))
    assert told.samples > 100
    assert (told.passed, told.max_position_error_m) == (untold.passed, untold.max_position_error_m)
    assert told.passed is (bias_lsb == 0)
    whole = analyze(read_log(path), PMIR, "exact").report
    streamed = analyze_file(path, PMIR, "exact", chunk_frames=97)
    assert json.dumps(streamed) == json.dumps(whole)
    assert [r["reference_start"] for r in whole["reboots"]] == ["power-up"]
    monitor, bridge = _live(lost)
    assert bridge.reboots == 1
    bridge.end_watch()
    verdicts = ["PASS" if whole["passed"] else "FAIL", monitor.health(lost[-1].timestamp)["state"],
                end_verdict(bridge).verdict]
    assert verdicts == (["PASS", "OK", "PASS"] if bias_lsb == 0 else
                        ["FAIL", "POSE WRONG", "FAIL"])
    for error_m in (whole["onboard_vs_reference"]["max_position_error_m"],
                    monitor.tracker.vs_reference.max_dpos_m,
                    bridge.tracker.vs_reference.max_dpos_m):
        assert error_m == pytest.approx(told.max_position_error_m, abs=0.1 * POSITION_LSB_M)


@pytest.mark.parametrize("twists", [6, 8])
@pytest.mark.parametrize("reboot_at", [32, 64])
def test_its_first_six_or_eight_twists_lost_too_the_second_summary_after_reads_it(
    reboot_at: int, twists: int, tmp_path: Path
) -> None:
    """The new firmware's first 6 (8) twists lost as well: the first twist heard (COUNTER 6, 8)
    comes after the summary that continues the boot summary; it falls below the old life's
    last, heard before the boot summary, by the second summary after it
    (``host.judge.latefall``). Before: FAIL by 93 mm (tick 32), 0.25 m (tick 64) in every
    judge, the checker PASSing."""
    messages = _drive(reboot_at)
    lost = _twists_lost(_lost(messages, reboot_at, 1, 0), reboot_at, twists)
    own, judges = _every_judge(lost, tmp_path / "six.log", _primed_t(messages, reboot_at))
    assert own.samples > 100
    assert own.passed
    assert [v for v, _ in judges.values()] == ["PASS", "OK", "PASS"]
    for name, (_, error_m) in judges.items():
        assert error_m == pytest.approx(own.max_position_error_m, abs=0.1 * POSITION_LSB_M), name


@pytest.mark.parametrize("bias_lsb", [100, 10_000])
@pytest.mark.parametrize("twists", [6, 8])
def test_a_pose_10_mm_or_1_m_off_after_six_or_eight_twists_lost_fails_every_judge(
    twists: int, bias_lsb: int, tmp_path: Path
) -> None:
    """The same reset at tick 32, 6 (8) twists lost, X 10 mm (1 m) off from the new power-up
    (E2E re-protected: a wrong firmware): the reboot told late, FAIL everywhere by what the
    checker finds."""
    messages = _drive(32)
    lost = _twists_lost(_lost(messages, 32, 1, bias_lsb), 32, twists)
    own, judges = _every_judge(lost, tmp_path / "wrong.log", _primed_t(messages, 32))
    assert not own.passed
    assert own.max_position_error_m > 0.9 * bias_lsb * POSITION_LSB_M
    assert [v for v, _ in judges.values()] == ["FAIL", "POSE WRONG", "FAIL"]
    for name, (_, error_m) in judges.items():
        assert error_m == pytest.approx(own.max_position_error_m, abs=0.1 * POSITION_LSB_M), name
