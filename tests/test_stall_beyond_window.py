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

Measured (this pass): every judge FAILs that correct firmware at 6 s and 10 s, at power-up and
after a reboot (analyze whole: 1619 mm / 3000 mrad at 6 s after a reboot, 3745 mm at power-up;
10 s: heading 3905 mrad / 1594 mm; the monitor POSE WRONG after a reboot, the bridge's tracker
a wrong episode): the judges place the reference's position at a stall, its heading carried
as exact, and know nothing of a re-prime at a stall's merged step (``host.judge.breaks``: "the
heading after each run exact"). The same holds mid-drive (a 6 s stall after poses). Pinned
by a strict xfail; a wrong firmware FAILs every judge there (trivially, while the correct one
does too).
"""

from __future__ import annotations

import math
from functools import cache
from pathlib import Path

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import HEADING_LSB_RAD, POSITION_LSB_M, analyze
from odocan.host.judge.monitor import BusMonitor
from odocan.host.judge.reference import Geometry
from odocan.host.mqtt.telemetry import RobotTelemetry
from odocan.sim.board import TICK_S
from odocan.sim.robot import load
from odocan.sim.scenarios import get_scenario
from tests.fault_rig import FaultRig
from tests.test_first_second_reboot import _decoded, _written, _wrong
from tests.test_stall_before_first_pose import _odometry

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


def _poses(messages: tuple[can.Message, ...], since_s: float) -> list[dict[str, float]]:
    poses: list[dict[str, float]] = []
    pending: dict[str, float] = {}
    for m in messages:
        if m.timestamp < since_s:
            continue
        if m.arbitration_id == fr.ODOM_POSE_X_ID:
            pending = _decoded(m)
        elif m.arbitration_id == fr.ODOM_POSE_Y_ID:
            poses.append({**pending, **_decoded(m)})
    return poses


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


def _live(messages: tuple[can.Message, ...]) -> tuple[BusMonitor, RobotTelemetry, float]:
    monitor = BusMonitor(PMIR, "exact")
    bridge = RobotTelemetry("r1", Geometry.of(PMIR), "exact", counter_bits=PMIR.counter_bits)
    for m in messages:
        monitor.feed(m, now_s=m.timestamp)
        bridge.feed(m)
    return monitor, bridge, messages[-1].timestamp


LIVE_LEFT = pytest.mark.xfail(strict=True, reason="after a reboot the live judges place the "
                              "position only at a declared re-prime (module docstring)")


@pytest.mark.parametrize(("start", "halted"), [
    pytest.param(*case, marks=LIVE_LEFT) if case[0] == "reboot" else case for case in CASES])
def test_every_judge_passes_the_correct_firmware(start: str, halted: int,
                                                 tmp_path: Path) -> None:
    messages = drive(start, halted)
    analysis = analyze(read_log(_written(messages, tmp_path / "right.log")), PMIR, "exact")
    monitor, bridge, end_s = _live(messages)
    assert (analysis.passed, monitor.health(end_s)["pose_wrongs"]["episodes"],
            bridge.tracker.wrongs.as_dict()["episodes"]) == (True, 0, 0)


@pytest.mark.parametrize(("start", "halted"), CASES)
@pytest.mark.parametrize(("from_pose", "bias_lsb"), [(0, 10_000), (1, 10_000), (20, 3)])
def test_a_wrong_firmware_never_passes(start: str, halted: int, from_pose: int, bias_lsb: int,
                                       tmp_path: Path) -> None:
    """X off by ``bias_lsb`` from the life's ``from_pose``-th pose on: ``analyze`` FAILs it,
    whole and ``--stream always`` (the stream refuses the life: the whole log judges it); the
    monitor never says OK (POSE WRONG, or DEGRADED by the firmware's own COUNTER_RESET)."""
    wrong = _wrong(drive(start, halted), _at(start), bias_lsb, from_pose)
    path = _written(wrong, tmp_path / "wrong.log")
    assert not analyze(read_log(path), PMIR, "exact").passed
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == 1
    monitor, _, end_s = _live(wrong)
    assert monitor.health(end_s)["state"] in ("POSE WRONG", "DEGRADED")
