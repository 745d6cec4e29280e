"""The live verdict's reasons follow the pose's current life (issue #11;
``host.judge.livestanding``, ``host.judge.monitor``).

A lockstep pmir on the circle, as in ``test_pose_offset_state``: its X off by 1.2 LSB from tick
300 (never corrected), or not; a host tool's set-pose to where the robot is at tick 600 (the pose
set anew, the reference restarted); a recorder gap (every frame of 40 ms missed) before it.

* The OK beside a reference placed again says so (``placed_why``), but only of the placements of
  the reference it is judged against: after the set-pose restarted it, the gap before is no
  reason of today's OK (it counted the watch's placements).
* A firmware DEGRADED (POSE_UNCERTAIN latched until the next set-pose) is judged as an OK one:
  POSE WRONG while the pose stands wrong in its current life, with the same reason; DEGRADED
  once the pose is set anew and right (it said POSE WRONG for the episodes of the life before).

Wrong or right by the independent dead reckoning of ``test_pose_offset_state`` (cantools,
float64: ``tests.independent_checker``), not by the judges under test.
"""

from __future__ import annotations

import math
from pathlib import Path

import can

from odocan.host.judge.livestanding import placed_why, pose_wrong_why
from odocan.host.judge.monitor import BusMonitor
from odocan.sim.board import TICK_S
from tests.fault_rig import open_virtual
from tests.test_health_rig import circle_rig
from tests.test_pose_offset_state import (
    OFF_AT,
    PMIR,
    Q40_PER_LSB,
    _checker_max_lsb,
    _watch,
    candump_written,
    set_pose_right,
)
from tests.test_pose_wrongs import _t_s
from tests.test_stall_bound import _messages

SET_AT, UNCERTAIN_AT, END = 600, 700, 900  # ticks
GAP_S = (4.0, 4.04)  # bus time the recorder missed (s)


def _drive(tmp_path: Path, offset_lsb: float, uncertain_at: int | None = None) -> Path:
    """The rig's frames as a candump log: X ``offset_lsb`` off from ``OFF_AT`` on, a set-pose
    of X, Y and HEADING to where the robot is at ``SET_AT``; POSE_UNCERTAIN latched at
    ``uncertain_at`` (DEGRADED until a set-pose)."""
    with circle_rig() as rig:
        heard: list[can.Message] = []
        rig.observers.append(lambda _k, frames: heard.extend(frames))
        tool = open_virtual(rig.channel)
        off_q40 = round(offset_lsb * Q40_PER_LSB)

        def hook(k: int) -> None:
            odometry = rig.ecu.odometry
            if k == OFF_AT:
                odometry.x_q40_m += off_q40
            if k == uncertain_at:
                rig.ecu.health.pose_uncertain()
            if k == SET_AT:
                set_pose_right(tool, odometry, off_q40, k)

        rig.before_board.append(hook)
        try:
            rig.run(END * TICK_S)
        finally:
            tool.shutdown()
    return candump_written(tmp_path / f"off_{offset_lsb}_{uncertain_at}.log", heard)


def _cut(path: Path, gap_s: tuple[float, float], until_s: float = math.inf) -> Path:
    """The log less its frames in ``gap_s`` (a recorder gap) and from ``until_s`` on."""
    cut = path.with_suffix(".gap.log")
    cut.write_text("".join(line for line in path.read_text().splitlines(True)
                           if not gap_s[0] <= _t_s(line) < gap_s[1] and _t_s(line) < until_s))
    return cut


def test_the_ok_reason_names_the_placements_of_the_current_reference(tmp_path: Path) -> None:
    whole = _drive(tmp_path, 0.0)
    assert _checker_max_lsb(whole, SET_AT * TICK_S) <= 1.0  # a correct firmware (then set
    path = _cut(whole, GAP_S)                                 # to its own pose, rounded)
    monitor, _, states = _watch(path)
    assert {state for t, state in states if t > 0.2} == {"OK"}
    breaks = monitor.snapshot(now_s=states[-1][0])["reference"]["breaks"]
    assert breaks["gap_placements"] == 1  # the watch's placements are still reported
    # the reference was started again at the set-pose: the gap before it is not its placement
    why = monitor.health(states[-1][0])["why"]
    assert why == [], why  # said "... placed again ... after 1 gap" before


def test_the_ok_reason_before_the_set_pose_names_the_gap(tmp_path: Path) -> None:
    """The guard: while the reference placed after the gap is the one judged, the OK says so."""
    path = _cut(_drive(tmp_path, 0.0), GAP_S, until_s=SET_AT * TICK_S - 0.1)
    monitor, _, states = _watch(path)
    why = monitor.health(states[-1][0])["why"]
    assert states[-1][1] == "OK"
    assert len(why) == 1
    assert why[0].startswith(
        "judged against the reference placed again where the firmware was after 1 gap")


def test_degraded_with_the_pose_standing_wrong_says_its_life(tmp_path: Path) -> None:
    path = _drive(tmp_path, 1.2, uncertain_at=OFF_AT)
    assert _checker_max_lsb(path, SET_AT * TICK_S) > 1.0  # wrong before the set-pose
    monitor = BusMonitor(PMIR)
    whys = []
    for msg in _messages(path):
        monitor.feed(msg, now_s=msg.timestamp)
        health = monitor.health(msg.timestamp)
        if OFF_AT * TICK_S + 0.2 < msg.timestamp < SET_AT * TICK_S:
            assert health["state"] == "POSE WRONG"
            assert health["why"][-1].startswith("firmware reports DEGRADED (POSE_UNCERTAIN")
            # the reasons an OK firmware's state gives: the latest sample, or this life's
            assert health["why"][:-1] == pose_wrong_why(monitor.tracker)  # was the watch's
            whys.append(health["why"][0])
    standing = [why for why in whys if why.startswith("the on-board pose was wrong in ")]
    assert standing
    assert all(" since the watch began, worst " in why for why in standing)
    assert any(why.startswith("on-board vs reference ") for why in whys)  # the latest sample


def test_degraded_after_the_pose_was_set_right_is_degraded(tmp_path: Path) -> None:
    path = _drive(tmp_path, 1.2, uncertain_at=UNCERTAIN_AT)
    assert _checker_max_lsb(path, SET_AT * TICK_S) > 1.0  # wrong before the set-pose
    monitor, _, states = _watch(path)
    late = {state for t, state in states if t > (UNCERTAIN_AT + 20) * TICK_S}
    assert late == {"DEGRADED"}  # was POSE WRONG: the episodes of the life before
    health = monitor.health(states[-1][0])
    assert health["pose_wrongs"]["episodes"] >= 1  # still latched for the watch
    assert "this_life" not in health["pose_wrongs"]
    assert health["why"][0].startswith("firmware reports DEGRADED (")


SILENT = range(500, 550)  # ticks the motor controller is silent; it restarts as it speaks again
HOLE_S = (4.7, 5.0)  # bus time the recorder missed before the restart (s)
SET_AFTER_RESTART = 800  # tick of the set-pose (the new start's hold over; DEGRADED till then)


def _restart_drive(tmp_path: Path) -> Path:
    """A correct firmware's frames as a candump log: the motor controller silent in ``SILENT``,
    then restarted (counters, COUNTER and CTRL_UPTIME from 0: the firmware DEGRADED,
    COUNTER_RESET, until a set-pose); a set-pose of X, Y and HEADING to where the firmware is at
    ``SET_AFTER_RESTART``; ``END`` ticks in all."""
    with circle_rig() as rig:
        heard: list[can.Message] = []
        rig.observers.append(lambda _k, frames: heard.extend(frames))
        rig.mute_sim(SILENT)
        tool = open_virtual(rig.channel)

        def hook(k: int) -> None:
            if k == SILENT[-1]:  # before the controller's next tick
                rig.sim.motor_controller.restart()
            if k == SET_AFTER_RESTART:
                set_pose_right(tool, rig.ecu.odometry, 0, k)

        rig.before_board.append(hook)
        try:
            rig.run(END * TICK_S)
        finally:
            tool.shutdown()
    return candump_written(tmp_path / "restart.log", heard)


def test_the_ok_after_a_set_pose_no_longer_names_the_unseen_restart_before_it(
    tmp_path: Path,
) -> None:
    """The recorder misses 0.3 s before the controller restart: an unseen restart, the
    reference restarted at the firmware's pose (``host.judge.livedark``), which the judge says
    beside its verdict. The set-pose after it starts the reference again at the pose set: the
    OK after it has no reason left (it named the restart: the watch's count)."""
    whole = _restart_drive(tmp_path)
    assert _checker_max_lsb(whole, SET_AFTER_RESTART * TICK_S) <= 1.0  # a correct firmware
    before = _cut(whole, HOLE_S, until_s=SET_AFTER_RESTART * TICK_S - 0.1)
    monitor, _, states = _watch(before)
    assert monitor.tracker.placer.dark.new_starts == 1  # an unseen restart, re-based on
    assert states[-1][1] == "DEGRADED"  # COUNTER_RESET, until the set-pose
    assert placed_why(monitor.tracker) == [  # the guard: said beside the firmware's state
        "the reference restarted at the firmware's pose after 1 unseen controller restart "
        "across a recorder hole (an offset it had then not judged)"]
    monitor, _, states = _watch(_cut(whole, HOLE_S))
    assert monitor.tracker.placer.dark.new_starts == 1  # the watch's count stays
    assert {state for t, state in states if t > SET_AFTER_RESTART * TICK_S + 0.2} == {"OK"}
    why = monitor.health(states[-1][0])["why"]
    assert why == [], why  # said "the reference restarted ... after 1 unseen controller ..."
