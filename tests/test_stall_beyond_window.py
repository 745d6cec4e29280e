"""A firmware stalled before its first pose LONGER than the live judges' 5 s window (issue #11).

``tests/test_stall_before_first_pose*.py`` halt the MCU 3 s; here 6 s and 10 s, at power-up
(the log's start) and after a reboot mid-drive (``tests.fault_rig.FaultRig``, pmir on the
circle; the reset's tick, or the power-up's, drains the receive FIFO: INIT, UPTIME 0, only its
ODOM_STATUS sent; then ``halted`` ticks of no MCU while the sim drives on).

What the firmware does (the tests' float64 odometry on cantools-decoded frames, independent of
the judges): it primes on the first frame its FIFO kept, steps the second, and then, its step's
plausibility bound after the overrun (the periods, plus a COUNTER cycle, plus the periods since
its last sample: about twice the stall) reaching half the 16-bit counters' range at pmir's
4 m/s (762 periods), it re-primes on the resumed frame (COUNTER_RESET in ERROR_MASK): the
motion across the stall is not in its pose. A 3 s stall stays below that bound (one merged
step, placed within the merge allowance by every judge).

Before issue #11's fix every judge FAILed that correct firmware at 6 s and 10 s, at power-up
and after a reboot (analyze whole: 1619 mm / 3000 mrad at 6 s after a reboot, 3745 mm at
power-up; 10 s: heading 3905 mrad / 1594 mm; the monitor POSE WRONG after a reboot, the
bridge's tracker a wrong episode), and mid-drive (a 6 s stall after 3 s of poses: 3169 mm /
3000 mrad): the judges placed the reference's position at a stall, its heading carried as
exact. Now the firmware's own word decides (``host.judge.stallreprime``: COUNTER_RESET newly
set after a stall long enough for its bound to reach the ambiguous step): ``analyze``
re-primes its reference there (the steps from the last frame the FIFO kept to the one it
re-primed on left out), the live judges hold the samples after the stall until that word and
restart their reference from the next pose (``host.judge.livereprime``); each reports a
``stall_reprime`` event, the monitor shows the firmware's DEGRADED. The same frames with the
word cleared get no re-prime (FAIL); a wrong firmware still FAILs every judge.
"""

from __future__ import annotations

import itertools
import math
from functools import cache
from pathlib import Path
from typing import Any

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M, analyze
from odocan.host.mqtt.endverdict import end_verdict
from odocan.host.mqtt.fleetjudge import watched_verdict
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim.board import TICK_S
from odocan.sim.robot import load
from odocan.sim.scenarios import get_scenario
from tests.fault_rig import FaultRig
from tests.test_first_second_reboot import _decoded, _reencoded, _written, _wrong
from tests.test_stall_before_first_pose import _odometry
from tests.test_stall_before_first_pose_after_reboot import _live, _poses

PMIR = load("pmir")
REBOOT = 500  # the reset's tick (5 s)
COUNTER_RESET_BIT = 1 << 9  # ERROR_MASK (firmware.errors.ErrorFlag.COUNTER_RESET)
CASES = [(start, halted) for start in ("power-up", "reboot") for halted in (600, 1000)]


def _at(start: str) -> int:
    return 0 if start == "power-up" else REBOOT


@cache
def drive(start: str, halted: int) -> tuple[can.Message, ...]:
    """pmir on the circle, the MCU started (power-up, tick 0) or reset (tick ``REBOOT``) with
    an empty receive FIFO, then halted ``halted`` ticks; 5 s more after it resumes."""
    at = _at(start)
    heard: list[can.Message] = []
    with FaultRig(scenario=get_scenario("circle", PMIR, duration_s=60.0)) as rig:
        def reset(k: int) -> None:
            if k == at:
                if at:
                    rig.board.reboot()
                while rig.fw_bus.recv(0) is not None:  # an empty FIFO: INIT, no frame to prime
                    pass
        rig.observers.append(lambda _k, got: heard.extend(got))
        rig.before_board.append(reset)
        rig.halted = lambda k: at < k <= at + halted
        rig.run((at + halted) * TICK_S + 5.0)
    return tuple(heard)


@pytest.mark.parametrize(("start", "halted"), CASES)
def test_the_firmware_reprimed_on_the_resumed_frame(start: str, halted: int) -> None:
    """Its first pose is its FIFO's two frames stepped (float64, within an LSB) and nothing of
    the stall: the merged step is metres away; its summary says COUNTER_RESET."""
    at = _at(start)
    messages = drive(start, halted)
    encoders = [_decoded(m) for m in messages if m.arbitration_id == fr.WHEEL_ENCODERS_ID]
    first = _poses(messages, at * TICK_S)[0]
    resumed = at + halted + 2
    assert int(first["ENC_COUNTER"]) == resumed % 16
    for frames, near in (([at + 1, at + 2], True), ([at + 1, at + 2, resumed], False)):
        odo = _odometry(encoders, frames)
        gap_m = math.hypot(odo.x - first["X"] * 1e-4, odo.y - first["Y"] * 1e-4)
        turn = abs(odo.heading - first["HEADING"] * 2 * math.pi / 65536)
        assert (gap_m <= POSITION_LSB_M and turn <= HEADING_LSB_RAD) is near, (gap_m, turn)
    masks = [int(_decoded(m)["ERROR_MASK"]) for m in messages
             if m.arbitration_id == fr.ODOM_STATUS_ID and m.timestamp > at * TICK_S
             and int(_decoded(m)["PAGE"]) == 0]
    assert any(mask & COUNTER_RESET_BIT for mask in masks)


@pytest.mark.parametrize(("start", "halted"), CASES)
def test_every_judge_passes_the_correct_firmware(start: str, halted: int,
                                                 tmp_path: Path) -> None:
    messages = drive(start, halted)
    analysis = analyze(read_log(_written(messages, tmp_path / "right.log")), PMIR, "exact")
    monitor, bridge, end_s = _live(messages)
    assert (analysis.passed, monitor.health(end_s)["pose_wrongs"]["episodes"],
            bridge.tracker.wrongs.as_dict()["episodes"]) == (True, 0, 0)
    assert monitor.health(end_s)["state"] == "DEGRADED"  # its own COUNTER_RESET: never OK
    assert [e["kind"] for e in analysis.report["events"]].count("stall_reprime") == 1
    assert _end_verdicts(bridge) == ("PASS", "PASS")
    for judge in (monitor, bridge):  # the live judges took the re-prime (power-up too)
        assert [e["kind"] for e in judge.events].count("stall_reprime") == 1


def _end_verdicts(bridge: RobotTelemetry) -> tuple[str, str]:
    """The fleet's end verdict (``watched_verdict``, which ends the watch) and the bridge's."""
    fleet = watched_verdict(bridge, 0, None)["verdict"]
    return fleet, end_verdict(bridge).verdict


@pytest.mark.parametrize(("start", "halted"), CASES)
@pytest.mark.parametrize(("from_pose", "bias_lsb"), [(0, 10_000), (1, 10_000), (20, 3)])
def test_a_wrong_firmware_never_passes(start: str, halted: int, from_pose: int, bias_lsb: int,
                                       tmp_path: Path) -> None:
    """X off by ``bias_lsb`` from the life's ``from_pose``-th pose on: ``analyze`` FAILs it,
    whole and ``--stream always`` (the stream refuses the life: the whole log judges it); the
    live judges say POSE WRONG and the bridge's and the fleet's end verdicts FAIL, at power-up
    too (a jump no re-prime explains from the power-up pose, once proven: ``livereprime``; X
    +1 m there was DEGRADED only and the end verdicts PASS)."""
    wrong = _wrong(drive(start, halted), _at(start), bias_lsb, from_pose)
    path = _written(wrong, tmp_path / "wrong.log")
    assert not analyze(read_log(path), PMIR, "exact").passed
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == 1
    monitor, bridge, end_s = _live(wrong)
    assert _end_verdicts(bridge) == ("FAIL", "FAIL")
    assert monitor.health(end_s)["state"] == "POSE WRONG"
    assert bridge.tracker.wrongs.as_dict()["episodes"] >= 1


@pytest.mark.parametrize("halted", [380, 450])
def test_a_reprime_within_the_window_at_power_up(halted: int) -> None:
    """A 3.8 s or 4.5 s halt at power-up: long enough to re-prime, short enough that frame 0 is
    still in the live window when the power-up is proven (the reference starts there before the
    firmware's word is taken). The right firmware passes live with its re-prime (before: POSE
    WRONG, both end verdicts FAIL, the heading carried as exact); X +1 m from its first pose
    FAILs."""
    monitor, bridge, end_s = _live(drive("power-up", halted))
    assert (monitor.health(end_s)["state"], bridge.tracker.wrongs.as_dict()["episodes"]) == (
        "DEGRADED", 0)
    assert [e["kind"] for e in bridge.events].count("stall_reprime") == 1
    assert _end_verdicts(bridge) == ("PASS", "PASS")
    monitor, bridge, end_s = _live(_wrong(drive("power-up", halted), 0, 10_000, 0))
    assert monitor.health(end_s)["state"] == "POSE WRONG"
    assert _end_verdicts(bridge) == ("FAIL", "FAIL")


def frame_zero_moved(messages: tuple[can.Message, ...]) -> tuple[can.Message, ...]:
    """The frames with encoder frame 0's LEFT_COUNT 5 counts back (E2E re-protected): the
    robot moved between frame 0 and frame 1 (the firmware never took frame 0: its FIFO was
    drained at tick 0), so which of them it primed on matters and the stall after its INIT at
    UPTIME 0 cannot tell (``host.judge.stallpowerup``)."""
    out, done = [], False
    for m in messages:
        if not done and m.arbitration_id == fr.WHEEL_ENCODERS_ID:
            signals = _decoded(m)
            signals["LEFT_COUNT"] = (int(signals["LEFT_COUNT"]) - 5) % (1 << 24)
            m = _reencoded(m, signals, fr.WHEEL_ENCODERS_DATA_IDS)
            done = True
        out.append(m)
    return tuple(out)


def _unproven(messages: tuple[can.Message, ...]) -> tuple[can.Message, ...]:
    """The frames with the first count page's ENC_E2E_OK 1000 off (E2E re-protected): no
    count the judges read proves the power-up; and frame 0 moved (``frame_zero_moved``), so
    neither does the stall after INIT at UPTIME 0 (``host.judge.stallpowerup``: with frame 0
    unmoved it proves the power-up, and the re-prime is bounded from (0, 0))."""
    out, done = [], False
    for m in frame_zero_moved(messages):
        if not done and m.arbitration_id == fr.ODOM_STATUS_ID and int(_decoded(m)["PAGE"]) == 2:
            signals = _decoded(m)
            signals["ENC_E2E_OK"] = (int(signals["ENC_E2E_OK"]) + 1000) & 0xFFFF
            m = _reencoded(m, signals, fr.ODOM_STATUS_DATA_IDS)
            done = True
        out.append(m)
    return tuple(out)


@pytest.mark.parametrize("from_pose", [None, 0, 1])
def test_an_unproven_power_up_reprime_never_passes(from_pose: int | None) -> None:
    """A re-prime declared after a 6 s halt at a power-up the live judges cannot prove: the
    firmware's first pose after it is adopted with nothing to bound it by, so the end verdicts
    are UNJUDGED, never a PASS, for the right firmware and a wrong one (X +1 m) alike (before:
    PASS)."""
    messages = drive("power-up", 600)
    if from_pose is not None:
        messages = _wrong(messages, 0, 10_000, from_pose)
    monitor, bridge, end_s = _live(_unproven(messages))
    assert not bridge.tracker.lives.power_up_proven
    assert monitor.health(end_s)["state"] != "OK"
    assert _end_verdicts(bridge) == ("UNJUDGED", "UNJUDGED")


MID = 300  # a mid-drive stall's start (3 s of poses before it)


@cache
def drive_mid(halted: int) -> tuple[can.Message, ...]:
    """pmir on the circle, its MCU halted ``halted`` ticks from tick ``MID`` (no reboot: its
    FIFO keeps the first frames after the halt), 5 s more after it resumes."""
    heard: list[can.Message] = []
    with FaultRig(scenario=get_scenario("circle", PMIR, duration_s=60.0)) as rig:
        rig.observers.append(lambda _k, got: heard.extend(got))
        rig.halted = lambda k: MID < k <= MID + halted
        rig.run((MID + halted) * TICK_S + 5.0)
    return tuple(heard)


def _undeclared(messages: tuple[can.Message, ...]) -> tuple[can.Message, ...]:
    """The firmware's frames with COUNTER_RESET cleared from every ODOM_STATUS summary (E2E
    re-protected): a firmware that re-primes without saying so."""
    out = []
    for m in messages:
        if m.arbitration_id == fr.ODOM_STATUS_ID and int(_decoded(m)["PAGE"]) == 0:
            signals = _decoded(m)
            signals["ERROR_MASK"] = int(signals["ERROR_MASK"]) & ~COUNTER_RESET_BIT
            m = _reencoded(m, signals, fr.ODOM_STATUS_DATA_IDS)
        out.append(m)
    return tuple(out)


@pytest.mark.parametrize("halted", [600, 1000])
def test_mid_drive_the_firmware_reprimes_and_every_judge_passes_it(halted: int,
                                                                   tmp_path: Path) -> None:
    """A long stall after poses: the firmware re-primes (its first pose after is its poses
    before, stepped over the FIFO's frames, without the stall's motion: the heading's turn over
    the stall is not in it) and declares it; every judge passes it and ``analyze`` reports the
    re-prime."""
    messages = drive_mid(halted)
    masks = [int(_decoded(m)["ERROR_MASK"]) for m in messages
             if m.arbitration_id == fr.ODOM_STATUS_ID and int(_decoded(m)["PAGE"]) == 0]
    assert not masks[0] & COUNTER_RESET_BIT
    assert masks[-1] & COUNTER_RESET_BIT
    analysis = analyze(read_log(_written(messages, tmp_path / "right.log")), PMIR, "exact")
    monitor, bridge, end_s = _live(messages)
    assert (analysis.passed, monitor.health(end_s)["pose_wrongs"]["episodes"],
            bridge.tracker.wrongs.as_dict()["episodes"]) == (True, 0, 0)
    assert monitor.health(end_s)["state"] == "DEGRADED"
    events = [e for e in analysis.report["events"] if e["kind"] == "stall_reprime"]
    assert len(events) == 1
    assert "declared by the firmware" in events[0]["detail"]
    for judge in (monitor, bridge):
        assert [e["kind"] for e in judge.events].count("stall_reprime") == 1
    assert main(["analyze", str(tmp_path / "right.log"), "--robot", "pmir", "--integrator",
                 "exact", "--stream", "always"]) == 0  # refused: judged whole


@pytest.mark.parametrize("halted", [600, 1000])
@pytest.mark.parametrize(("from_pose", "bias_lsb"), [(0, 10_000), (1, 10_000), (20, 3)])
def test_mid_drive_a_wrong_firmware_never_passes(halted: int, from_pose: int, bias_lsb: int,
                                                 tmp_path: Path) -> None:
    """X off from the ``from_pose``-th pose after the stall's start on: every judge FAILs it
    (the live ones: a jump beyond what the FIFO's frames and the re-prime explain is no
    declared re-prime, ``livereprime``)."""
    wrong = _wrong(drive_mid(halted), MID + 1, bias_lsb, from_pose)
    path = _written(wrong, tmp_path / "wrong.log")
    assert not analyze(read_log(path), PMIR, "exact").passed
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == 1
    monitor, bridge, end_s = _live(wrong)
    assert monitor.health(end_s)["state"] == "POSE WRONG"
    assert bridge.tracker.wrongs.as_dict()["episodes"] >= 1


@pytest.mark.parametrize(("messages", "at"), [
    pytest.param(lambda: drive("reboot", 600), REBOOT, id="reboot"),
    pytest.param(lambda: drive_mid(600), 0, id="mid-drive")])
def test_an_undeclared_reprime_gets_no_heading_replacement(messages: Any, at: int,
                                                           tmp_path: Path) -> None:
    """The same frames with COUNTER_RESET never said: the reference keeps its exact heading
    across the stall (no re-prime taken), and ``analyze`` FAILs the heading."""
    path = _written(_undeclared(messages()), tmp_path / "undeclared.log")
    analysis = analyze(read_log(path), PMIR, "exact")
    assert not analysis.passed
    assert analysis.report["onboard_vs_reference"]["max_heading_error_rad"] > 0.1
    assert not [e for e in analysis.report["events"] if e["kind"] == "stall_reprime"]
    monitor, bridge, end_s = _live(_undeclared(messages()))
    assert monitor.health(end_s)["pose_wrongs"]["episodes"] >= 1
    assert bridge.tracker.wrongs.as_dict()["episodes"] >= 1


TEN_MM_LSB = 100  # X off by 10 mm: beyond analyze's allowance, within the speed bound's reach
REPLAYED = [*CASES, ("mid-drive", 600), ("mid-drive", 1000)]


def _drive_at(start: str, halted: int) -> tuple[tuple[can.Message, ...], int]:
    """The drive and the tick the poses made wrong are counted from (``_wrong``)."""
    if start == "mid-drive":
        return drive_mid(halted), MID + 1
    return drive(start, halted), _at(start)


@pytest.mark.parametrize(("start", "halted"), REPLAYED)
@pytest.mark.parametrize("from_pose", [0, 1])
def test_ten_mm_off_after_the_reprime_fails_live(start: str, halted: int, from_pose: int,
                                                 tmp_path: Path) -> None:
    """X 10 mm off from the ``from_pose``-th pose after the stall's start (the first after
    the re-prime on: pose 0 is left out). ``analyze`` FAILs it (the re-primed pose held to the
    frames the FIFO kept); live, the re-prime's first pose is replayed from those frames
    (``reprimereplay``) and held to two LSBs of it: POSE WRONG, both end verdicts FAIL, the
    refusal told. Before: held only to the speed bound's reach (about 0.26 m), the pose was
    adopted: DEGRADED, both end verdicts PASS. The independent float64 odometry of the frames
    the firmware took (its FIFO's, then re-primed) puts the right pose 10 mm from the wrong
    one (power-up and reboot: the poses before a mid-drive stall are the firmware's)."""
    messages, at = _drive_at(start, halted)
    wrong = _wrong(messages, at, TEN_MM_LSB, from_pose)
    if start != "mid-drive":  # the pose after the left-out one, as the firmware made it
        assert _off_reprimed_m(messages, at, halted) <= POSITION_LSB_M
        assert _off_reprimed_m(wrong, at, halted) > 0.0099
    assert not analyze(read_log(_written(wrong, tmp_path / "wrong.log")), PMIR, "exact").passed
    monitor, bridge, end_s = _live(wrong)
    assert monitor.health(end_s)["state"] == "POSE WRONG"
    assert _end_verdicts(bridge) == ("FAIL", "FAIL")
    for judge in (monitor, bridge):
        kinds = [e["kind"] for e in judge.events]
        assert (kinds.count("stall_reprime_refused"), kinds.count("stall_reprime")) == (1, 0)


def _off_reprimed_m(messages: tuple[can.Message, ...], at: int, halted: int) -> float:
    """How far (m) the life's second pose lies from the float64 odometry of the frames the
    firmware took: primed on ``at + 1``, stepped to ``at + 2`` (its FIFO), re-primed on the
    resumed frame and stepped frame by frame to the one the pose names (its ENC_COUNTER)."""
    encoders = [_decoded(m) for m in messages if m.arbitration_id == fr.WHEEL_ENCODERS_ID]
    pose = _poses(messages, at * TICK_S)[1]
    resumed = at + halted + 2
    named = resumed + (int(pose["ENC_COUNTER"]) - resumed) % 16
    odo = _odometry(encoders, [at + 1, at + 2])
    for a, b in itertools.pairwise(range(resumed, named + 1)):
        odo.step(*(round((encoders[b][side] - encoders[a][side] + 32768) % 65536 - 32768)
                   for side in ("LEFT_COUNT", "RIGHT_COUNT")))
    return math.hypot(odo.x - pose["X"] * 1e-4, odo.y - pose["Y"] * 1e-4)


def _unheard(messages: tuple[can.Message, ...], ticks: range) -> tuple[can.Message, ...]:
    """The frames without the encoder frames of ``ticks`` (a recorder that lost them)."""
    return tuple(m for m in messages if m.arbitration_id != fr.WHEEL_ENCODERS_ID
                 or round(m.timestamp / TICK_S) not in ticks)


@pytest.mark.parametrize(("start", "halted"), [("reboot", 600), ("mid-drive", 600)])
@pytest.mark.parametrize("bias_lsb", [0, TEN_MM_LSB])
def test_a_reprime_whose_frames_were_not_heard_is_never_a_pass(start: str, halted: int,
                                                               bias_lsb: int) -> None:
    """Two of the frames the firmware's FIFO kept lost by the recorder: the live judge cannot
    replay the re-prime, so it holds the first pose after it to the speed bound's reach only
    and says so (the event), and the end verdicts are UNJUDGED, the right firmware's and the
    one 10 mm off alike: never a FAIL of the right one, never a PASS that hides 10 mm
    (before: PASS, PASS for both)."""
    messages, at = _drive_at(start, halted)
    if bias_lsb:
        messages = _wrong(messages, at, bias_lsb, 1)
    monitor, bridge, end_s = _live(_unheard(messages, range(at + 1, at + 3)))
    assert monitor.health(end_s)["state"] == "DEGRADED"
    assert _end_verdicts(bridge) == ("UNJUDGED", "UNJUDGED")
    for judge in (monitor, bridge):
        said = [e["detail"] for e in judge.events if e["kind"] == "stall_reprime"]
        assert len(said) == 1
        assert "was not replayed" in said[0]


@pytest.mark.parametrize("start", ["power-up", "reboot", "mid-drive"])
@pytest.mark.parametrize("bias_lsb", [0, TEN_MM_LSB])
def test_a_frame_lost_after_the_reprime_still_lets_it_be_replayed(start: str,
                                                                   bias_lsb: int) -> None:
    """One encoder frame after the re-prime lost by the recorder (three after the resumed
    one, between the samples held): the samples before it replay the re-prime, so the right
    firmware still PASSes and 10 mm off still FAILs (not the wide bound's UNJUDGED for both)."""
    messages, at = _drive_at(start, 600)
    if bias_lsb:
        messages = _wrong(messages, at, bias_lsb, 1)
    resumed = (MID if start == "mid-drive" else at) + 602
    monitor, bridge, end_s = _live(_unheard(messages, range(resumed + 3, resumed + 4)))
    assert bridge.tracker.reprime.wide == 0
    assert monitor.health(end_s)["state"] == ("POSE WRONG" if bias_lsb else "DEGRADED")
    assert _end_verdicts(bridge) == (("FAIL", "FAIL") if bias_lsb else ("PASS", "PASS"))
