"""A firmware silent more than a second and then restarted, recorded by a recorder that stamps
every ODOM_STATUS frame 50 ms late, must not be FAILed live (issue #11, rule 5: a FAIL must never
blame a correct firmware).

pmir on the circle in the lockstep rig: its MCU halted ``halted`` ticks from tick ``MID`` (a
process killed), its receive FIFO cleared, then reset (``FirmwareBoard.reboot``: a new process on
a fresh socket) at tick ``reboot_at``; it primes on that tick's encoder frame and sends its
power-up pose (COUNTER 0, X 0) and its boot summary (UPTIME 0, COUNTER 0) in that tick. The
log's ODOM_STATUS frames all stamped ``late_s`` later, the log re-sorted by time: the boot summary
then comes after the new firmware's first three poses, and the reboot is told only from UPTIME
going back. Before 27991a37 the live judges dated the new life from that late summary and held
its first poses to the old life's reference: 1.78 m, one POSE WRONG episode in the monitor and
the bridge, its end verdict FAIL on a correct firmware (a trial's live log: 1.46 m). Now the new
life starts at the run of poses counting from COUNTER 0 (``bootticks.told_run_s``).

Independent of the judges: cantools decodes the frames, and the test's float64 odometry
(``tests.independent_checker``) checks each life's poses from (0, 0, 0) at the frame it primed on
(the old life's from the log's start, the new one's from its power-up pose's frame): the correct
firmware is right, the one 1 m off after the reboot is not. ``analyze`` (whole) agrees.
"""

from __future__ import annotations

from functools import cache
from itertools import pairwise
from pathlib import Path

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.host.mqtt.endverdict import end_verdict
from odocan.host.mqtt.fleetjudge import watched_verdict
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim.board import TICK_S
from odocan.sim.scenarios import get_scenario
from tests import independent_checker as ic
from tests.fault_rig import FaultRig
from tests.test_first_second_reboot import PMIR, _decoded, _reset_seen, _robot, _written, _wrong
from tests.test_stall_before_first_pose_after_reboot import _live
from tests.test_status_stamped_late import _status_late

MID = 300  # the last tick the old firmware runs (3 s of poses)
HALTS = [150, 185]  # ticks the MCU is silent: 1.5 s, 1.85 s (the trial's)
LATE_S = 0.05  # the recorder's lateness on ODOM_STATUS
ONE_M_LSB = 10_000  # X off by 1 m (0.1 mm LSB)


def _reboot_at(halted: int) -> int:
    return MID + halted + 1


@cache
def drive(halted: int) -> tuple[can.Message, ...]:
    """pmir on the circle, its MCU silent ``halted`` ticks after ``MID``, then a new firmware
    on an empty receive FIFO at ``_reboot_at``; 4 s more. Every frame heard, on time."""
    at = _reboot_at(halted)
    heard: list[can.Message] = []
    with FaultRig(scenario=get_scenario("circle", PMIR, duration_s=60.0)) as rig:
        def restart(k: int) -> None:
            if k == at - 1:  # the killed process's socket gone: nothing of the halt waits
                while rig.fw_bus.recv(0) is not None:
                    pass
            if k == at:
                rig.board.reboot()
        rig.observers.append(lambda _k, got: heard.extend(got))
        rig.before_board.append(restart)
        rig.halted = lambda k: MID < k < at
        rig.run(at * TICK_S + 4.0)
    return tuple(heard)


def _recorded(halted: int, bias_lsb: int = 0) -> tuple[can.Message, ...]:
    """The drive as the late recorder wrote it; X ``bias_lsb`` off from the new life's first
    pose on when ``bias_lsb``."""
    messages = drive(halted)
    if bias_lsb:
        messages = _wrong(messages, _reboot_at(halted), bias_lsb)
    return _status_late(messages, LATE_S)


def _float64(messages: tuple[can.Message, ...], halted: int, tmp_path: Path
             ) -> tuple[ic.Verdict, ic.Verdict]:
    """The test's own odometry of each life: the old one from the log's start up to its halt,
    the new one from the encoder frame its power-up pose names (``_reset_seen``), each from
    (0, 0, 0)."""
    primed_t = _reset_seen(drive(halted), _reboot_at(halted))
    lives = (tuple(m for m in messages if m.timestamp < (MID + 1) * TICK_S),
             tuple(m for m in messages if m.timestamp >= primed_t))
    old, new = (ic.check(_written(life, tmp_path / f"life{i}.log"), _robot(), "exact",
                         lambda _t: (0.0, 0.0, 0.0)) for i, life in enumerate(lives))
    assert min(old.samples, new.samples) > 100
    return old, new


def _heard_before_boot_summary(messages: tuple[can.Message, ...], from_s: float
                               ) -> tuple[list[int], int, int]:
    """cantools: the COUNTERs of the ODOM_POSE_X frames heard from ``from_s`` up to the first
    ODOM_STATUS summary after it, that summary's UPTIME, and the UPTIME of the summary before
    ``from_s``."""
    summaries = [(m.timestamp, _decoded(m)) for m in messages
                 if m.arbitration_id == fr.ODOM_STATUS_ID and _decoded(m)["PAGE"] == 0]
    before = [s for t, s in summaries if t < from_s][-1]
    t_boot, boot = next((t, s) for t, s in summaries if t >= from_s)
    counters = [int(_decoded(m)["COUNTER"]) for m in messages
                if m.arbitration_id == fr.ODOM_POSE_X_ID and from_s <= m.timestamp < t_boot]
    assert int(boot["COUNTER"]) == 0
    return counters, int(boot["UPTIME"]), int(before["UPTIME"])


def _end_verdict(bridge: RobotTelemetry) -> str:
    return end_verdict(bridge).verdict


@pytest.mark.parametrize("halted", HALTS)
def test_the_premise_a_silent_firmware_restarted_and_its_boot_summary_heard_late(
    halted: int, tmp_path: Path
) -> None:
    """No pose for more than a second; the new firmware's first three poses (COUNTER 0, 1, 2)
    are heard before its boot summary (UPTIME 0), after the old one's of UPTIME 3; the
    float64 odometry finds both lives right (the wrong firmware's new life 1 m off)."""
    messages = _recorded(halted)
    at_s = _reboot_at(halted) * TICK_S
    poses = [m.timestamp for m in messages if m.arbitration_id == fr.ODOM_POSE_X_ID]
    assert max(b - a for a, b in pairwise(poses)) > 1.0
    counters, uptime_s, uptime_before_s = _heard_before_boot_summary(messages, at_s)
    assert (counters, uptime_s) == ([0, 1, 2], 0)
    assert uptime_before_s > 0  # UPTIME goes back: the reboot's word
    old, new = _float64(messages, halted, tmp_path)
    assert (old.passed, new.passed) == (True, True)
    _, wrong = _float64(_recorded(halted, ONE_M_LSB), halted, tmp_path)
    assert wrong.max_position_error_m == pytest.approx(1.0, abs=1e-3)


@pytest.mark.parametrize("halted", HALTS)
def test_the_correct_firmware_passes_live_and_in_analyze(halted: int, tmp_path: Path) -> None:
    """Before 27991a37: one POSE WRONG episode (1.78 m) in the monitor and the bridge, the
    bridge's end verdict FAIL."""
    messages = _recorded(halted)
    monitor, bridge, end_s = _live(messages)
    assert [e["kind"] for e in monitor.events].count("reboot") == 1
    assert bridge.reboots == 1
    assert (monitor.health(end_s)["pose_wrongs"]["episodes"],
            bridge.tracker.wrongs.as_dict()["episodes"]) == (0, 0)
    assert monitor.health(end_s)["state"] == "OK"
    for tracker in (monitor.tracker, bridge.tracker):
        assert tracker.vs_reference.max_dpos_m < 1e-3
    assert _end_verdict(bridge) == "PASS"
    path = _written(messages, tmp_path / "right.log")
    analysis = analyze(read_log(path), PMIR, "exact")
    assert analysis.passed, analysis.report["onboard_vs_reference"]
    assert len(analysis.report["reboots"]) == 1
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "never"]) == 0


@pytest.mark.parametrize("halted", HALTS)
def test_a_firmware_one_metre_off_after_the_reboot_fails_every_judge(
    halted: int, tmp_path: Path
) -> None:
    messages = _recorded(halted, ONE_M_LSB)
    monitor, bridge, end_s = _live(messages)
    assert monitor.health(end_s)["state"] == "POSE WRONG"
    assert bridge.tracker.wrongs.as_dict()["episodes"] >= 1
    assert _end_verdict(bridge) == "FAIL"
    path = _written(messages, tmp_path / "wrong.log")
    assert not analyze(read_log(path), PMIR, "exact").passed
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "never"]) == 1


@pytest.mark.parametrize("halted", HALTS)
def test_the_fleets_end_verdict_passes_the_correct_firmware(halted: int) -> None:
    """Before the withdrawal reached the loss allowance's largest error: FAIL, "position vs
    reference 1776 mm (beyond the loss allowance)" (the new life's first poses against the old
    life's reference, settled when it ended)."""
    _, bridge, _ = _live(_recorded(halted))
    verdict = watched_verdict(bridge, 0, None)
    assert verdict["verdict"] == "PASS", verdict
    assert verdict["max_dpos_beyond_allowance_m"] < 1e-3


@pytest.mark.parametrize("halted", HALTS)
def test_the_fleets_end_verdict_fails_a_firmware_one_metre_off_after_the_reboot(
    halted: int
) -> None:
    """The withdrawal takes back only the new life's poses against the old reference: its
    poses against its own reference, 1 m off, still FAIL the fleet's verdict."""
    _, bridge, _ = _live(_recorded(halted, ONE_M_LSB))
    verdict = watched_verdict(bridge, 0, None)
    assert verdict["verdict"] == "FAIL", verdict
    assert verdict["max_dpos_beyond_allowance_m"] > 0.9  # its new life's (1.02 m)
