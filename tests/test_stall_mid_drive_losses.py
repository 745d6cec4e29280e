"""A firmware stalled mid-drive (not before a life's first pose): its FIFO overrun's losses
are the stall placement's, no loss span's (``losses.life_placements``, issue #11 rule 5).

Lockstep pmir on the circle (``tests.fault_rig.FaultRig``): the MCU runs no tick from
``STALL + 1`` to ``STALL + HALTED`` (3 s, inside the live judges' 5 s window, below the re-prime
bound) while the sim drives on. On resuming, its FIFO-locked controller hands it the frames
that waited (encoder frames ``STALL + 1``, ``STALL + 2``) and overruns the rest; it takes the
next frame, ``RESUMED_AT``, as one step. ENC_E2E_LOST grows by 11 (the COUNTER's jump mod 16).
The float64 odometry of the tests (``independent_checker._Odometry`` on cantools-decoded
frames) shows the firmware's poses after the stall are exactly that.

The judges place the reference's position again at the first sample after the stall, within
the merge allowance of every set of runs lost between the last sample before it and that one.
The page after the stall also opened a loss span over those frames (11 lost in a run among
the overrun's): 0.29 mm (0.18 mm live) on top of the placement for the same frames. X 3 LSB
off from 0.1 s after the stall on PASSed ``analyze`` whole and streamed (0.076 mm beyond the
allowance), 2 LSB PASSed the live judges. Now those frames are the placement's in every judge
(``analyze``, the streamed ``SpanDrops``, ``livelosses.LiveAllowance.stalled_at``): the span's
count stays whole for the frames outside the placement (the pages cannot say where the 11
lie: 0.105 mm of allowance at the frames after it), so 3 LSB FAILs every judge (analyze 0.150
mm beyond), 2 LSB the live ones (0.130 mm beyond); the correct firmware stays 0.068 mm off.
2 LSB from 0.1 s on still PASSes ``analyze`` (not asserted): the segment after the stall is
placed at the middle of its samples (``reference_path.raw_segment_offsets``), which splits
such an edit, and the 11 frames' whole count takes 0.105 mm more.
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
from odocan.host.judge.analysis import POSITION_LSB_M, analyze
from odocan.sim.board import TICK_S
from odocan.sim.robot import load
from odocan.sim.scenarios import get_scenario
from tests.fault_rig import FaultRig
from tests.test_first_second_reboot import _decoded, _written, _wrong
from tests.test_stall_before_first_pose import _odometry
from tests.test_stall_before_first_pose_after_reboot import _live, _poses

PMIR = load("pmir")
STALL = 500  # the last tick the MCU runs before the stall (5 s)
HALTED = 300  # ticks it then runs none (3 s)
RESUMED_AT = STALL + HALTED + 2  # the encoder frame its first pose after the stall names
RUN_S = 10.0


@cache
def drive() -> tuple[can.Message, ...]:
    """``RUN_S`` of pmir on the circle, the MCU halted after tick ``STALL``."""
    heard: list[can.Message] = []
    with FaultRig(scenario=get_scenario("circle", PMIR, duration_s=60.0)) as rig:
        rig.observers.append(lambda _k, got: heard.extend(got))
        rig.halted = lambda k: STALL < k <= STALL + HALTED
        rig.run(RUN_S)
    return tuple(heard)


def _float64_gap_m(messages: tuple[can.Message, ...], k: int) -> float:
    """How far (m) the ``k``-th pose sent after the stall (``k`` >= 0) lies from the float64
    odometry of the frames the firmware took: every one to ``STALL + 2`` (its FIFO), then
    ``RESUMED_AT`` as one step, then every frame to the one the pose names."""
    encoders = [_decoded(m) for m in drive() if m.arbitration_id == fr.WHEEL_ENCODERS_ID]
    pose = _poses(messages, (STALL + HALTED) * TICK_S)[k]
    named = RESUMED_AT + 2 * k
    assert int(pose["ENC_COUNTER"]) == named % 16
    odo = _odometry(encoders, [*range(STALL + 3), *range(RESUMED_AT, named + 1)])
    return math.hypot(odo.x - pose["X"] * 1e-4, odo.y - pose["Y"] * 1e-4)


def test_the_stall_overran_the_fifo_and_the_firmware_counted_it() -> None:
    """The premise: ENC_E2E_LOST 0 before the stall, 11 after (the overrun, counted mod 16);
    the poses after it are the firmware's FIFO then one step (float64, within an LSB), the
    fine path 0.5 mm away."""
    pages = [_decoded(m) for m in drive() if m.arbitration_id == fr.ODOM_STATUS_ID]
    lost = [p["ENC_E2E_LOST"] for p in pages if p["PAGE"] == 2]
    assert set(lost) == {0, 11}
    assert lost == sorted(lost)
    for k in (0, 1, 5, 60):
        assert _float64_gap_m(drive(), k) <= POSITION_LSB_M
    encoders = [_decoded(m) for m in drive() if m.arbitration_id == fr.WHEEL_ENCODERS_ID]
    fine = _odometry(encoders, list(range(RESUMED_AT + 1)))
    first = _poses(drive(), (STALL + HALTED) * TICK_S)[0]
    assert math.hypot(fine.x - first["X"] * 1e-4, fine.y - first["Y"] * 1e-4) > 4e-4


def test_the_correct_firmware_passes_every_judge(tmp_path: Path) -> None:
    path = _written(drive(), tmp_path / "stall.log")
    analysis = analyze(read_log(path), PMIR, "exact")
    assert analysis.passed, analysis.report["onboard_vs_reference"]
    assert analysis.report["reference_breaks"]["stall_placements"] == 1
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == 0
    monitor, bridge, end_s = _live(drive())
    assert monitor.health(end_s)["pose_wrongs"]["episodes"] == 0
    for tracker in (monitor.tracker, bridge.tracker):
        assert tracker.stall.stalls == 1
        assert tracker.wrongs.as_dict()["episodes"] == 0


def _evidence(messages: tuple[can.Message, ...], from_pose: int) -> None:
    """The correct firmware is within one LSB of the float64 odometry there, the wrong one
    more than one LSB off."""
    assert _float64_gap_m(drive(), from_pose) <= POSITION_LSB_M
    assert _float64_gap_m(messages, from_pose) > POSITION_LSB_M


@pytest.mark.parametrize("from_pose", [5, 60])
def test_three_lsb_after_the_stall_fail_analyze(tmp_path: Path, from_pose: int) -> None:
    """X 3 LSB off from the ``from_pose``-th pose after the stall on (0.1 s, 1.2 s later):
    before, PASS whole and streamed (0.076 mm, 0.071 mm beyond the allowance: the overrun's
    11 frames allowed 0.29 mm again on top of the placement)."""
    messages = _wrong(drive(), STALL + HALTED, 3, from_pose)
    _evidence(messages, from_pose)
    path = _written(messages, tmp_path / "wrong.log")
    assert not analyze(read_log(path), PMIR, "exact").passed
    assert main(["analyze", str(path), "--robot", "pmir", "--integrator", "exact",
                 "--stream", "always"]) == 1


@pytest.mark.parametrize("from_pose", [5, 60])
def test_two_lsb_after_the_stall_fail_the_live_judges(from_pose: int) -> None:
    """X 2 LSB off from the ``from_pose``-th pose after the stall on: before, no episode in
    the monitor or the bridge (0.068 mm, 0.073 mm beyond their allowance)."""
    messages = _wrong(drive(), STALL + HALTED, 2, from_pose)
    _evidence(messages, from_pose)
    monitor, bridge, end_s = _live(messages)
    assert monitor.health(end_s)["pose_wrongs"]["episodes"] >= 1
    for tracker in (monitor.tracker, bridge.tracker):
        assert tracker.wrongs.as_dict()["episodes"] >= 1
