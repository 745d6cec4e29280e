"""A bare APPLY just after a firmware re-primed at a stall before its first pose (issue #11: "a
PASS/OK must never hide a wrong pose"; ``host.judge.reprimekept``).

The case: pmir (``tests.fault_rig.FaultRig``), the MCU reset at tick ``REBOOT`` with its receive
FIFO drained, halted 4.9 s, 6 s or 10 s (long enough for its step bound to reach half the
counters' range: it re-primes on resuming and says so, COUNTER_RESET, the stall's motion left
out by design: ``stallreprime``), then a bare APPLY (nothing staged: the pose must stay) 2 or 3
ticks after it resumed; the firmware's set_pose adds ``off`` to its X (0: the correct firmware).

Measured before (``analyze``, the monitor, the bridge), straight and circle alike: the kept
check was not made ("its power-up pose not known": ``setposekept._refusal_said`` withdrew the
stall rule) and the life after the APPLY was judged from a fitted start: X +1 m and +10 mm
PASSed ``analyze`` on every halt; live, the straight drive's +1 m was OK too (the placement
owed after the stall absorbed 986 mm), the circle's was POSE WRONG. Now ``analyze`` bounds the
pose at the APPLY by the travel of every frame the firmware can have integrated (its FIFO's
before the stall, those from the frame it re-primed on): +1 m FAILs everywhere; +10 mm FAILs
the straight drive (at rest after the stall: a 7.6 mm bound) and is named "judged only within
54 mm" on the circle (moving: which frames it took is not on the log), never a silent PASS.
Live (``livekept._reprimed``) the same bound, the FIFO's frames at the speed bound when the
window no longer holds them (166 mm on pmir): +1 m is POSE WRONG on both judges, and the
bridge's end verdict is UNJUDGED with the bound named (``livekept.coarse_why``), not PASS.
Without an APPLY the re-prime is judged (``stallreprime``) and PASSes: the hole was the APPLY's.
Found then (a strict xfail), fixed since (``host.judge.acrosscut``): on the circle with the
APPLY 3 ticks after, ``analyze`` FAILed the correct firmware at the lone sample before the
APPLY (its re-prime's word came after the cut); swept over 64 drives in
``tests/test_reprime_sweep.py``.
"""

from __future__ import annotations

import re
from functools import cache
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.firmware import frames as fr
from odocan.firmware.errors import ErrorMask
from odocan.firmware.odometry import Odometry
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import analyze
from odocan.host.mqtt.endverdict import end_verdict
from odocan.host.report.summary import kept_failures, kept_unjudged
from odocan.sim.scenarios import get_scenario
from tests import host_frames as hf
from tests.fault_rig import FaultRig, reset_then_send
from tests.test_staged_reboot import PMIR, _live, _written, _x_by_frame

REBOOT = 10  # the reset's tick (0.1 s)
AFTER_TICKS = 200  # ticks driven after the halt
LSB_Q40 = round(1e-4 * 2**40)  # one position LSB (0.1 mm) in the firmware's Q40 metres
METRE_Q40 = 10_000 * LSB_Q40


@cache
def drive(scenario: str, halted: int, after: int | None,
          off_q40: int = 0) -> tuple[can.Message, ...]:
    """The module docstring's drive: halted ``halted`` ticks, the APPLY ``after`` ticks after
    it resumed (None: none); set_pose adds ``off_q40`` to X."""
    apply_at = None if after is None else REBOOT + halted + after
    apply = [(fr.ODOM_SET_POSE_ID, hf.pack_odom_set_pose(0, fr.SetPoseField.APPLY, 0,
                                                          ErrorMask()))]
    with pytest.MonkeyPatch.context() as patch, FaultRig(
            scenario=get_scenario(scenario, PMIR, duration_s=60.0)) as rig:
        set_pose = Odometry.set_pose
        patch.setattr(Odometry, "set_pose",
                      lambda self, x, y, h: set_pose(self, x + off_q40, y, h))
        rig.halted = lambda k: REBOOT < k <= REBOOT + halted
        return reset_then_send(rig, REBOOT, apply_at, apply, REBOOT + halted + AFTER_TICKS)


def _report(messages: tuple[can.Message, ...], path: Path) -> dict[str, Any]:
    report = analyze(read_log(_written(messages, path)), PMIR, "exact").report
    assert isinstance(report, dict)
    return report


def _kept(report: dict[str, Any]) -> dict[str, Any]:
    [event] = [e for e in report["events"] if e["kind"] == "set_pose"]
    assert isinstance(event["kept"], dict), event.get("kept_not_judged")
    return event["kept"]


@pytest.mark.parametrize(("scenario", "halted", "after"), [
    ("straight", 490, 2), ("straight", 600, 3), ("straight", 1000, 3), ("circle", 600, 2),
    ("circle", 1000, 2)])
def test_the_correct_firmware_passes_and_the_check_is_made(
        scenario: str, halted: int, after: int, tmp_path: Path) -> None:
    right = drive(scenario, halted, after)
    assert _x_by_frame(right) == _x_by_frame(drive(scenario, halted, None))  # nothing moved
    report = _report(right, tmp_path / "right.log")
    assert report["passed"], report["onboard_vs_reference"]
    kept = _kept(report)
    assert kept["passed"]
    assert kept["reprimed"]
    assert not kept_failures(report)


def test_without_the_apply_the_re_prime_is_the_firmware_s_own(tmp_path: Path) -> None:
    """The hole was the APPLY's: without it the re-prime is judged (its event) and PASSes."""
    report = _report(drive("straight", 600, None), tmp_path / "none.log")
    assert report["passed"]
    assert [e["kind"] for e in report["events"]].count("stall_reprime") == 1


@pytest.mark.parametrize(("scenario", "halted", "after"), [
    ("straight", 490, 2), ("straight", 490, 3), ("straight", 600, 2), ("straight", 1000, 3),
    ("circle", 490, 3), ("circle", 1000, 2)])
def test_a_bare_apply_that_moves_x_by_a_metre_fails(
        scenario: str, halted: int, after: int, tmp_path: Path) -> None:
    """Before: PASS (the check not made, the life after it fitted)."""
    report = _report(drive(scenario, halted, after, METRE_Q40), tmp_path / "wrong.log")
    kept = _kept(report)
    assert kept["passed"] is False
    assert kept["position_jump_m"] > 0.99
    assert not report["passed"]
    assert kept_failures(report)


def test_ten_millimetres_fail_the_straight_drive_at_rest(tmp_path: Path) -> None:
    """After the straight drive's 4 s the robot rests: the bound is the FIFO's frames (7.6 mm)."""
    report = _report(drive("straight", 600, 3, 100 * LSB_Q40), tmp_path / "ten.log")
    assert _kept(report)["passed"] is False
    assert not report["passed"]


def test_ten_millimetres_within_the_bound_are_said_not_silent(tmp_path: Path) -> None:
    """On the circle the frames the firmware took are not on the log: +10 mm is within the
    bound, and the verdict line says how coarse the check was (before: "not judged")."""
    report = _report(drive("circle", 600, 2, 100 * LSB_Q40), tmp_path / "ten.log")
    kept = _kept(report)
    assert kept["passed"]
    assert kept["bound_m"] > 0.01
    assert any("judged only within" in line for line in kept_unjudged(report))


@pytest.mark.parametrize(("scenario", "halted", "after"), [
    ("straight", 490, 2), ("straight", 490, 3), ("straight", 1000, 3), ("circle", 600, 2)])
def test_a_bare_apply_that_moves_x_by_a_metre_is_pose_wrong_live(
        scenario: str, halted: int, after: int) -> None:
    """Before, on the straight drive: OK (the placement owed after the stall absorbed 986 mm);
    now ``livekept`` bounds it as ``analyze`` does (the FIFO's frames at the speed bound when
    the window no longer holds them: 166 mm on pmir)."""
    wrong = drive(scenario, halted, after, METRE_Q40)
    monitor, bridge = _live(wrong)
    for judge in (monitor, bridge):
        assert judge.tracker.wrongs.count > 0
    assert monitor.health(wrong[-1].timestamp)["state"] == "POSE WRONG"


@pytest.mark.parametrize(("scenario", "halted", "after"), [
    ("straight", 490, 2), ("straight", 1000, 3), ("circle", 490, 3), ("circle", 1000, 2)])
def test_the_correct_firmware_is_ok_live(scenario: str, halted: int, after: int) -> None:
    right = drive(scenario, halted, after)
    monitor, bridge = _live(right)
    for judge in (monitor, bridge):
        assert judge.tracker.wrongs.count == 0
    [event] = [e for e in monitor.tracker.restarts.events if e["kind"] == "set_pose"]
    assert event["kept"]["passed"]
    assert monitor.health(right[-1].timestamp)["state"] == "OK"


def test_the_bridge_s_end_verdict_says_the_coarse_check_not_pass() -> None:
    """Live the FIFO's frames before a 6 s halt are out of the window: the bound is the speed
    bound's (166 mm on pmir), so +10 mm passes the check. The bridge's verdict is UNJUDGED,
    the bound named (before: PASS), for the correct firmware and the +10 mm one alike."""
    for off_q40 in (0, 100 * LSB_Q40):
        _, bridge = _live(drive("straight", 600, 2, off_q40))
        bridge.end_watch()
        verdict = end_verdict(bridge)
        assert verdict.verdict == "UNJUDGED", verdict
        # the bound named: the kept check's, or the re-prime's own when its FIFO frames were
        # not heard either (livereprime's unbounded_why comes first then)
        assert re.search(r"(judged only within|held only to the speed bound) .*\d+ mm",
                         verdict.reason), verdict.reason


@pytest.mark.parametrize("halted", [490, 1000])
def test_the_correct_firmware_on_the_circle_with_the_apply_3_ticks_after_passes(
        halted: int, tmp_path: Path) -> None:
    """Before: FAIL (a strict xfail): the life before the APPLY ended 30 ms after the stall,
    so the firmware's COUNTER_RESET word (its next summary) lay in the next life's frames, and
    its lone sample was judged with the exact heading across the re-prime (2.38 rad off). Now
    that life's word is read on past the cut (``acrosscut.later_word``); the whole sweep:
    ``tests/test_reprime_sweep.py``."""
    report = _report(drive("circle", halted, 3), tmp_path / "right.log")
    assert _kept(report)["passed"]  # (the kept check holds)
    assert report["passed"], report["onboard_vs_reference"]


@pytest.mark.parametrize(("scenario", "halted", "after"), [
    ("spin", 400, 2), ("spin", 800, 2), ("square", 400, 3), ("square", 800, 2)])
def test_the_power_up_rule_does_not_hold_across_a_re_prime(
        scenario: str, halted: int, after: int, tmp_path: Path) -> None:
    """Where ``powerup.life_powered_up`` proves the power-up (spin, square: the robot still at
    the start), the APPLY was judged from (0, 0, 0) through the stall's frames, which the
    re-primed firmware left out: its kept check FAILed the correct firmware (942 mrad on the
    spin after 4 s, 789 mm on the square). Now a re-prime told withdraws that rule: bounded.
    (Other parts of these logs' verdicts FAIL the correct firmware still: see the report.)"""
    right = _kept(_report(drive(scenario, halted, after), tmp_path / "right.log"))
    wrong = _kept(_report(drive(scenario, halted, after, METRE_Q40), tmp_path / "wrong.log"))
    assert right["passed"], right
    assert right["reprimed"]
    assert wrong["passed"] is False
