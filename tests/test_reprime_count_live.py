"""The live judges take a re-primed power-up's frames from the first count page's ENC_E2E_LOST
(issue #11; ``host.judge.livereprimecount``), as ``analyze`` does (``reprimecount``).

The rig: pmir's MCU powered up with its receive FIFO drained (INIT at UPTIME 0, COUNTER 0), the
log starting there, then halted ``halted`` ticks: on the circle 5 s into the drive (moving at
power-up), or spinning / on the random drive from rest at tick 0. The firmware primes on frame
1 (frame 0 came before its drained read), steps frame 2 and re-primes on the resumed frame
(``halted + 2``): ENC_E2E_LOST ``(halted + 2 - 2 - 1) mod 16``. The evidence: an independent
float64 odometry (``tests.independent_checker``) of cantools-decoded frames.

Measured before: the correct firmware's live end verdicts UNJUDGED ("the encoder frame it primed
on is not known") at the 6 and 10 s halts, ``analyze`` PASS. Now the pairs the count allows
from frame 0 do not meet its first pose after the re-prime, those from frame 1 do: PASS, the
frame named (``power_up_primed_on``); wrong firmwares from that pose on still FAIL live; a
recorder stamping ODOM_STATUS late (the count unmoved) makes no false FAIL; a count no fitting
pair allows, E2E-valid, is the firmware's claim its poses contradict: FAIL, as ``analyze`` (it was
UNJUDGED live); the same count altered on the wire (its CRC broken) blames no correct firmware.
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
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M, analyze
from odocan.sim.board import TICK_S
from odocan.sim.scenarios import get_scenario
from tests.fault_rig import FaultRig
from tests.test_first_second_reboot import DB, _decoded, _reencoded, _written, _wrong
from tests.test_stall_before_first_pose import _odometry
from tests.test_stall_before_first_pose_after_reboot import _live, _poses
from tests.test_stall_beyond_window import PMIR, _end_verdicts
from tests.test_status_stamped_late import _status_late

AT = {"circle": 500, "spin": 0, "random": 0}  # the power-up's tick (circle: moving)
CASES = [("circle", 600), ("circle", 1000), ("spin", 600), ("random", 600), ("random", 1000)]


@cache
def drive(scenario: str, halted: int) -> tuple[can.Message, ...]:
    """The module docstring's log: from the power-up's tick on, 5 s after the MCU resumed."""
    at, heard = AT[scenario], []
    with FaultRig(scenario=get_scenario(scenario, PMIR, duration_s=60.0)) as rig:
        def power_up(k: int) -> None:
            if k == at:
                if at:
                    rig.board.reboot()
                while rig.fw_bus.recv(0) is not None:  # drained: nothing to prime on
                    pass
        rig.observers.append(lambda _k, got: heard.extend(got))
        rig.before_board.append(power_up)
        rig.halted = lambda k: at < k <= at + halted
        rig.run((at + halted) * TICK_S + 5.0)
    return tuple(m for m in heard if m.timestamp >= at * TICK_S - 1e-9)


def _off(messages: tuple[can.Message, ...], primed: int, f: int, r: int) -> tuple[float, float]:
    """How far (m, rad) the firmware's first pose after the re-prime lies from the float64
    odometry primed on ``primed``, stepped to ``f``, re-primed on ``r`` and stepped to the
    frame the pose names."""
    encoders = [_decoded(m) for m in messages if m.arbitration_id == fr.WHEEL_ENCODERS_ID]
    pose = _poses(messages, messages[0].timestamp)[1]
    named = r + (int(pose["ENC_COUNTER"]) - int(encoders[r]["COUNTER"])) % 16
    odo = _odometry(encoders, list(range(primed, f + 1)))
    for a, b in itertools.pairwise(range(r, named + 1)):
        odo.step(*(round((encoders[b][side] - encoders[a][side] + 32768) % 65536 - 32768)
                   for side in ("LEFT_COUNT", "RIGHT_COUNT")))
    turn = math.remainder(odo.heading - pose["HEADING"] * math.tau / 65536, math.tau)
    return math.hypot(odo.x - pose["X"] * 1e-4, odo.y - pose["Y"] * 1e-4), abs(turn)


def _lost(messages: tuple[can.Message, ...]) -> int:
    pages = [_decoded(m) for m in messages if m.arbitration_id == fr.ODOM_STATUS_ID]
    return next(int(p["ENC_E2E_LOST"]) for p in pages if "ENC_E2E_LOST" in p)


def _primed_on(tracker: Any) -> list[int]:
    return [e["encoder_frame"] for e in tracker.restarts.events
            if e["kind"] == "power_up_primed_on"]


@pytest.mark.parametrize(("scenario", "halted"), CASES)
def test_the_count_pins_the_frame_it_primed_on(scenario: str, halted: int,
                                                tmp_path: Path) -> None:
    """The checker: primed on frame 1 (f 2, r ``halted + 2``, the page's count) within an LSB;
    from frame 0 no pair the count allows within two. Live: PASS naming frame 1, as
    ``analyze`` PASSes it."""
    messages, resumed = drive(scenario, halted), halted + 2
    lost = _lost(messages)
    assert (resumed - 2 - 1) % 16 == lost
    pos_m, turn_rad = _off(messages, 1, 2, resumed)
    assert pos_m <= POSITION_LSB_M
    assert turn_rad <= HEADING_LSB_RAD
    for f in range(6):  # from frame 0: the pairs (f, f + resumed - 2) the count allows
        pos_m, turn_rad = _off(messages, 0, f, f + resumed - 2)
        assert pos_m > 2 * POSITION_LSB_M or turn_rad > 2 * HEADING_LSB_RAD
    analysis = analyze(read_log(_written(messages, tmp_path / "right.log")), PMIR, "exact")
    assert analysis.passed
    assert [(e["kind"], e["encoder_frame"]) for e in analysis.report["events"]
            if e["kind"] in ("power_up_primed_on", "stall_reprime")] == [
        ("power_up_primed_on", 1), ("stall_reprime", resumed)]
    monitor, bridge, end_s = _live(messages)
    assert monitor.health(end_s)["state"] != "POSE WRONG"
    assert _end_verdicts(bridge) == ("PASS", "PASS")
    for tracker in (monitor.tracker, bridge.tracker):
        assert _primed_on(tracker) == [1]  # as analyze names it, and its re-prime's frame:
        assert all(f"re-primed on {resumed}," in e["detail"] for e in tracker.restarts.events
                   if e["kind"] == "power_up_primed_on")
        assert tracker.wrongs.as_dict()["episodes"] == 0


@pytest.mark.parametrize(("scenario", "halted"), [("circle", 600), ("spin", 600),
                                                  ("random", 1000)])
@pytest.mark.parametrize("bias_lsb", [10_000, 100, 3, -3])
def test_a_wrong_firmware_fails_live(scenario: str, halted: int, bias_lsb: int,
                                     tmp_path: Path) -> None:
    """X ``bias_lsb`` off (1 m, 10 mm, 3 LSB) from the first pose after the re-prime on: more
    than an LSB from the checker's odometry; every judge FAILs it."""
    wrong = _wrong(drive(scenario, halted), AT[scenario], bias_lsb, 1)
    assert _off(wrong, 1, 2, halted + 2)[0] > POSITION_LSB_M
    assert not analyze(read_log(_written(wrong, tmp_path / "wrong.log")), PMIR, "exact").passed
    monitor, bridge, end_s = _live(wrong)
    assert monitor.health(end_s)["state"] == "POSE WRONG"
    assert _end_verdicts(bridge) == ("FAIL", "FAIL")


@pytest.mark.parametrize(("scenario", "halted"), [("circle", 600), ("random", 1000)])
@pytest.mark.parametrize("late_s", [0.015, 0.05])
def test_a_late_recorder_makes_no_false_fail(scenario: str, halted: int, late_s: float,
                                             tmp_path: Path) -> None:
    """ODOM_STATUS stamped ``late_s`` late: the count page no longer proves the power-up (its
    tick bound moved past frames it counted) but the count it carries is the same: the replay
    it pins proves it (``livereprime.ReprimeHold._pinned``; before, the first pose adopted
    unbounded, UNJUDGED); the correct firmware PASSes live, as ``analyze`` PASSes it."""
    messages = _status_late(drive(scenario, halted), late_s)
    assert analyze(read_log(_written(messages, tmp_path / "late.log")), PMIR, "exact").passed
    monitor, bridge, end_s = _live(messages)
    assert monitor.health(end_s)["state"] != "POSE WRONG"
    assert _end_verdicts(bridge) == ("PASS", "PASS")
    assert _primed_on(bridge.tracker) == [1]


@pytest.mark.parametrize("bias_lsb", [3, -3, 100])
def test_a_late_recorder_never_passes_a_wrong_firmware(bias_lsb: int) -> None:
    """The same late recorder (50 ms), X ``bias_lsb`` off from the first pose after the
    re-prime on: no pair the count allows fits, the power-up stays unproven: never a PASS."""
    messages = _status_late(_wrong(drive("circle", 600), AT["circle"], bias_lsb, 1), 0.05)
    _monitor, bridge, _end_s = _live(messages)
    assert "PASS" not in _end_verdicts(bridge)
    assert _primed_on(bridge.tracker) == []


def _count_moved(messages: tuple[can.Message, ...], by: int) -> tuple[can.Message, ...]:
    """The first count page's ENC_E2E_LOST ``by`` more (E2E re-protected)."""
    out, moved = [], False
    for m in messages:
        signals = _decoded(m) if m.arbitration_id == fr.ODOM_STATUS_ID else {}
        if "ENC_E2E_LOST" in signals and not moved:
            moved, signals["ENC_E2E_LOST"] = True, (int(signals["ENC_E2E_LOST"]) + by) % 16
            m = _reencoded(m, signals, fr.ODOM_STATUS_DATA_IDS)
        out.append(m)
    return tuple(out)


@pytest.mark.parametrize(("scenario", "halted"), [("circle", 600), ("random", 600)])
def test_a_count_no_fitting_pair_allows_fails(scenario: str, halted: int,
                                              tmp_path: Path) -> None:
    """The page's count 8 off, E2E re-protected (no pair it allows meets the first pose; others
    do): the page passed its E2E check, so the count is the firmware's own claim, and its
    poses contradict it: a wrong firmware output. ``analyze`` FAILs it (it keeps the pairs the
    count allows); live, before UNJUDGED, now POSE WRONG and FAIL, the refusal saying why."""
    messages = _count_moved(drive(scenario, halted), 8)
    assert not analyze(read_log(_written(messages, tmp_path / "moved.log")), PMIR,
                       "exact").passed
    monitor, bridge, end_s = _live(messages)
    assert monitor.health(end_s)["state"] == "POSE WRONG"
    assert _end_verdicts(bridge) == ("FAIL", "FAIL")
    for tracker in (monitor.tracker, bridge.tracker):
        assert [e for e in tracker.restarts.events if e["kind"] == "stall_reprime_refused"
                and "ENC_E2E_LOST 15 does not allow" in e["detail"]]
        assert _primed_on(tracker) == []


def _count_flipped(messages: tuple[can.Message, ...]) -> tuple[can.Message, ...]:
    """The first count page's ENC_E2E_LOST 8 more on the wire, its CHECKSUM left as it was (a
    bus or recorder artefact, which the E2E check refuses)."""
    out, flipped = [], False
    for m in messages:
        signals = _decoded(m) if m.arbitration_id == fr.ODOM_STATUS_ID else {}
        if "ENC_E2E_LOST" in signals and not flipped:
            flipped, signals["ENC_E2E_LOST"] = True, (int(signals["ENC_E2E_LOST"]) + 8) % 16
            m = can.Message(arbitration_id=m.arbitration_id, is_extended_id=False,
                            data=DB.encode_message(m.arbitration_id, signals, scaling=False),
                            timestamp=m.timestamp)
        out.append(m)
    return tuple(out)


@pytest.mark.parametrize(("scenario", "halted"), [("circle", 600), ("random", 600)])
def test_a_count_altered_on_the_wire_blames_no_correct_firmware(scenario: str, halted: int,
                                                                tmp_path: Path) -> None:
    """The first count page's ENC_E2E_LOST altered without its CRC (a bus or recorder
    artefact): refused by the E2E check, it is no claim of the firmware; the next count page
    carries the same count. The correct firmware PASSes every judge."""
    messages = _count_flipped(drive(scenario, halted))
    assert messages != drive(scenario, halted)
    assert analyze(read_log(_written(messages, tmp_path / "flipped.log")), PMIR,
                   "exact").passed
    monitor, bridge, end_s = _live(messages)
    assert monitor.health(end_s)["state"] != "POSE WRONG"
    assert _end_verdicts(bridge) == ("PASS", "PASS")
    for tracker in (monitor.tracker, bridge.tracker):  # the next page's, the firmware's count
        assert tracker.reprime.count.lost == _lost(drive(scenario, halted))
        assert _primed_on(tracker) == [1]
