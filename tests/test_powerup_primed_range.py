"""A power-up primed on frame 1 (its FIFO drained at tick 0), the recorder stamping every
ODOM_STATUS frame 0 .. 50 ms late (issue #11: "a PASS must never hide a wrong pose").

The first count page's k (the encoder frames before it less ENC_E2E_OK) grows with the late
stamp: 1 at 0 ms, 2 at 10 and 15 ms, 3 at 20 ms, 6 at 50 ms; the first pose names frame 2.
Before: from 20 ms on the first pose vetoed k and the start was fitted, so a firmware 1 m off
(or 10 mm) PASSed ``analyze`` (whole, ``--stream``), the monitor (OK) and the bridge; at 10-15
ms k = 2 was taken while the firmware primed on 1, so on a robot moving at power-up the correct
firmware FAILed every judge. Now the life is judged from (0, 0, 0) on each frame 0 ..
min(k, n) (``host.judge.primedrange``; live the one its first pose fits:
``host.judge.liveprimed``).

Two drives: ``drive("power-up", 0)`` with frame 0 moved (the robot still over frames 1 .. 3),
and ``moving()``: the MCU powered up 1 s into the circle, the robot moving (frames 0 .. 3
differ), the recorder started at its power-up. The evidence is the test's own: k and the named
frame from cantools-decoded frames, the float64 odometry (``_odometry``) from each candidate
frame to the poses: within an LSB from frame 1 for the correct firmware; at least 5 mm off from
every candidate for the wrong ones.
"""

from __future__ import annotations

import contextlib
import functools
import io
import math
from pathlib import Path

import can
import pytest

from odocan.firmware import frames as fr
from odocan.host.cli.app import main
from odocan.host.io.logs import read_log
from odocan.host.judge.analysis import POSITION_LSB_M, analyze
from odocan.host.judge.primedon import PRIMED_KIND
from odocan.host.judge.primedrange import primed_frames
from odocan.sim.board import TICK_S
from odocan.sim.scenarios import get_scenario
from tests.fault_rig import FaultRig
from tests.test_first_second_reboot import _decoded, _written, _wrong
from tests.test_powerup_primed_late import _first_named, _primed_on, _right, _status_late
from tests.test_stall_before_first_pose import _odometry
from tests.test_stall_before_first_pose_after_reboot import _live, _poses
from tests.test_stall_beyond_window import PMIR, _end_verdicts

LATE_S = (0.0, 0.01, 0.015, 0.02, 0.05)
K_BY_LATE = {0.0: 1, 0.01: 2, 0.015: 2, 0.02: 3, 0.05: 6}
DRIVES = ("still", "moving")
BIASES = (0, 100, 10_000)  # X LSBs off from the first pose on: right, 10 mm, 1 m
POWER_UP_TICK = 100  # ``moving``: the MCU's first tick, 1 s into the circle


@functools.cache
def moving() -> tuple[can.Message, ...]:
    """pmir on the circle, the MCU halted for its first second (no tick run: UPTIME 0 at its
    first), its FIFO drained at its first tick (it primes on the next frame); the frames from
    that tick on, 5 s."""
    heard: list[can.Message] = []
    with FaultRig(scenario=get_scenario("circle", PMIR, duration_s=60.0)) as rig:
        def drain(k: int) -> None:
            if k == POWER_UP_TICK:
                while rig.fw_bus.recv(0) is not None:
                    pass
        rig.observers.append(lambda k, got: heard.extend(got) if k >= POWER_UP_TICK else None)
        rig.before_board.append(drain)
        rig.halted = lambda k: k < POWER_UP_TICK
        rig.run(POWER_UP_TICK * TICK_S + 5.0)
    return tuple(heard)


@functools.cache
def _frames(drive: str, bias_lsb: int, late_s: float) -> tuple[can.Message, ...]:
    right = _right(True) if drive == "still" else moving()
    return _status_late(_wrong(right, 0, bias_lsb, 0) if bias_lsb else right, late_s)


def _encoders(messages: tuple[can.Message, ...]) -> list[dict[str, float]]:
    return [_decoded(m) for m in messages if m.arbitration_id == fr.WHEEL_ENCODERS_ID]


def _gap_m(messages: tuple[can.Message, ...], p: int, index: int) -> float:
    """How far the ``index``-th pose lies from the float64 odometry primed on frame ``p``
    (two encoder frames a pose, the first naming frame 2)."""
    pose, named = _poses(messages, 0.0)[index], 2 + 2 * index
    encoders = _encoders(messages)
    assert int(pose["ENC_COUNTER"]) == int(encoders[named]["COUNTER"])
    odo = _odometry(encoders, list(range(p, named + 1)))
    return math.hypot(odo.x - pose["X"] * 1e-4, odo.y - pose["Y"] * 1e-4)


@pytest.mark.parametrize("drive", DRIVES)
@pytest.mark.parametrize("late_s", LATE_S)
def test_the_evidence(drive: str, late_s: float) -> None:
    """k grows with the late stamp, the first pose names frame 2: the candidates 0 .. min(k, 2)
    hold frame 1, from which the correct firmware's poses are the float64 odometry; the wrong
    ones are 5 mm or more off from every candidate (the robot moving: the candidates differ)."""
    right = _frames(drive, 0, late_s)
    k, named = _primed_on(right), _first_named(right)
    assert (k, named) == (K_BY_LATE[late_s], 2)
    candidates = list(range(min(k, named) + 1))
    assert sorted(primed_frames(k, named)) == candidates
    for index in (0, 1, 20):
        assert _gap_m(right, 1, index) <= POSITION_LSB_M
        for bias in (100, 10_000):
            assert min(_gap_m(_frames(drive, bias, late_s), p, index)
                       for p in candidates) > 0.005
    moved = [_gap_m(right, p, 0) for p in (0, 2)]
    assert all(gap > 0.004 for gap in moved) == (drive == "moving")


def _analyzed(messages: tuple[can.Message, ...], path: Path) -> tuple[bool, list[int], int]:
    """``analyze`` whole (passed, the frames its power-up event says) and ``--stream always``'s
    exit code."""
    _written(messages, path)
    analysis = analyze(read_log(path), PMIR, "exact")
    frames = [e["encoder_frame"] for e in analysis.report["events"] if e["kind"] == PRIMED_KIND]
    with contextlib.redirect_stdout(io.StringIO()):
        code = main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                     "--stream", "always"])
    return analysis.passed, frames, code


@pytest.mark.parametrize("drive", DRIVES)
@pytest.mark.parametrize("late_s", LATE_S)
def test_the_correct_firmware_passes_every_judge(drive: str, late_s: float,
                                                 tmp_path: Path) -> None:
    """Before: FAIL in every judge at 10 and 15 ms on the moving drive (k = 2 taken)."""
    messages = _frames(drive, 0, late_s)
    passed, frames, code = _analyzed(messages, tmp_path / "right.log")
    assert (passed, code) == (True, 0)
    assert frames == [1] if drive == "moving" else len(frames) == 1
    monitor, bridge, end_s = _live(messages)
    assert (monitor.health(end_s)["state"], _end_verdicts(bridge)) == ("OK", ("PASS", "PASS"))
    for tracker in (monitor.tracker, bridge.tracker):
        assert tracker.max_beyond_allowance_m <= POSITION_LSB_M
        assert tracker.lives.primed_from is not None
        chosen, candidates = tracker.lives.primed_from
        assert chosen in candidates
        assert sorted(candidates) == list(range(min(K_BY_LATE[late_s], 2) + 1))
        if drive == "moving":
            assert chosen == 1


@pytest.mark.parametrize("drive", DRIVES)
@pytest.mark.parametrize("late_s", LATE_S)
@pytest.mark.parametrize("bias_lsb", [100, 10_000])
def test_a_wrong_firmware_fails_every_judge(drive: str, late_s: float, bias_lsb: int,
                                            tmp_path: Path) -> None:
    """Before: PASS in every judge from 20 ms on (k vetoed, the start fitted)."""
    messages = _frames(drive, bias_lsb, late_s)
    passed, frames, code = _analyzed(messages, tmp_path / "wrong.log")
    assert (passed, code, len(frames)) == (False, 1, 1)
    monitor, bridge, end_s = _live(messages)
    assert (monitor.health(end_s)["state"], _end_verdicts(bridge)) == ("POSE WRONG",
                                                                        ("FAIL", "FAIL"))
    for tracker in (monitor.tracker, bridge.tracker):
        assert tracker.max_beyond_allowance_m > 0.8 * bias_lsb * POSITION_LSB_M
