"""A firmware powered up while the robot moves, halted long enough to re-prime (issue #11: "a
FAIL must never blame a correct firmware"; ``host.judge.livereprimecount``).

The case: pmir on the circle (``tests.fault_rig.FaultRig``), its odometry MCU powered up at tick
``AT`` (a reset with its receive FIFO drained: INIT at UPTIME 0, COUNTER 0) while the robot
drives at 0.5 m/s, the log starting there; then halted ``halted`` ticks (4.5, 6, 10 s): it
primes on frame 1 (frame 0 came before its drained read), steps frame 2, and re-primes on the
resumed frame (COUNTER_RESET). Frame 0 to 1 moves 4.7 mm and 6.3 mrad.

Measured before: ``analyze`` (whole and ``--stream``) PASSed
the correct firmware (``primedon``: judged from frames 0 and 1) but the live judges replayed the
re-prime from the power-up pose on frame 0 only: its first pose 0.99 mm from the replay, the
monitor POSE WRONG and both end verdicts FAIL. Now the replay tries frame 0 and frame 1: no
false FAIL (the end verdicts UNJUDGED, as at a stall with frame 0 moved: which frame it primed
on is unproven live), and X 3 LSB off from its first pose still FAILs every judge (2 LSB does
at 4.5 and 6 s, not at 10 s, where -2 LSB passes every judge before and after: the stall
placement's 0.1 mm). The evidence: an independent float64 odometry (cantools-decoded frames)
of the frames the firmware took.
"""

from __future__ import annotations

import itertools
import math
from functools import cache
from pathlib import Path

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import POSITION_LSB_M, analyze
from odocan.sim.board import TICK_S
from odocan.sim.scenarios import get_scenario
from tests.fault_rig import FaultRig
from tests.test_first_second_reboot import _decoded, _written, _wrong
from tests.test_stall_before_first_pose import _odometry
from tests.test_stall_before_first_pose_after_reboot import _live, _poses
from tests.test_stall_beyond_window import PMIR, _end_verdicts

AT = 500  # the power-up's tick (the robot driven 5 s on the circle by then)


@cache
def drive(halted: int) -> tuple[can.Message, ...]:
    """The module docstring's log: from the power-up's tick on, 5 s after the MCU resumed."""
    heard: list[can.Message] = []
    with FaultRig(scenario=get_scenario("circle", PMIR, duration_s=60.0)) as rig:
        def power_up(k: int) -> None:
            if k == AT:
                rig.board.reboot()
                while rig.fw_bus.recv(0) is not None:  # drained: nothing to prime on
                    pass
        rig.observers.append(lambda _k, got: heard.extend(got))
        rig.before_board.append(power_up)
        rig.halted = lambda k: AT < k <= AT + halted
        rig.run((AT + halted) * TICK_S + 5.0)
    return tuple(m for m in heard if m.timestamp >= AT * TICK_S - 1e-9)


def _off_m(messages: tuple[can.Message, ...], halted: int, primed_on: int) -> float:
    """How far (m) the second pose lies from the float64 odometry of primed on ``primed_on``,
    stepped to frame 2, re-primed on the resumed frame and stepped to the pose's frame."""
    encoders = [_decoded(m) for m in messages if m.arbitration_id == fr.WHEEL_ENCODERS_ID]
    pose = _poses(messages, 0.0)[1]
    resumed = halted + 2
    named = resumed + (int(pose["ENC_COUNTER"]) - int(encoders[resumed]["COUNTER"])) % 16
    odo = _odometry(encoders, list(range(primed_on, 3)))
    for a, b in itertools.pairwise(range(resumed, named + 1)):
        odo.step(*(round((encoders[b][side] - encoders[a][side] + 32768) % 65536 - 32768)
                   for side in ("LEFT_COUNT", "RIGHT_COUNT")))
    return math.hypot(odo.x - pose["X"] * 1e-4, odo.y - pose["Y"] * 1e-4)


@pytest.mark.parametrize("halted", [450, 600, 1000])
def test_no_judge_fails_the_correct_firmware(halted: int, tmp_path: Path) -> None:
    """It primed on frame 1, not 0 (the float64 evidence); every judge: no FAIL."""
    messages = drive(halted)
    assert _off_m(messages, halted, 1) <= POSITION_LSB_M
    assert _off_m(messages, halted, 0) > 5 * POSITION_LSB_M
    path = _written(messages, tmp_path / "right.log")
    assert analyze(read_log(path), PMIR, "exact").passed
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == 0
    monitor, bridge, end_s = _live(messages)
    assert monitor.health(end_s)["state"] != "POSE WRONG"
    for tracker in (monitor.tracker, bridge.tracker):
        assert tracker.wrongs.as_dict()["episodes"] == 0
    assert "FAIL" not in _end_verdicts(bridge)


@pytest.mark.parametrize("halted", [450, 600, 1000])
@pytest.mark.parametrize("bias_lsb", [3, -3])
def test_three_lsb_off_fails_every_judge(halted: int, bias_lsb: int, tmp_path: Path) -> None:
    """X ``bias_lsb`` off from the first pose on: more than an LSB from either frame's
    float64 odometry; every judge FAILs it."""
    wrong = _wrong(drive(halted), AT, bias_lsb, 0)
    assert min(_off_m(wrong, halted, p) for p in (0, 1)) > POSITION_LSB_M
    path = _written(wrong, tmp_path / "wrong.log")
    assert not analyze(read_log(path), PMIR, "exact").passed
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == 1
    monitor, bridge, end_s = _live(wrong)
    assert monitor.health(end_s)["state"] == "POSE WRONG"
    assert _end_verdicts(bridge) == ("FAIL", "FAIL")
