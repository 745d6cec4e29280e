"""Lockstep drives whose new firmware's first tick integrates a backlog (issue #11: a FAIL must
never blame a correct firmware).

Before ``FirmwareBoard.join_bus`` an ``odocan firmware`` process opened its bus ~0.7 s before
its first tick: its first tick got ~79 queued frames at once, its 32-slot mailbox kept the
oldest 32 and dropped the rest, and its first pose named a frame two COUNTER laps before the
newest of its ENC_COUNTER (``/work/findings/backlog_first_tick_b5.log``, ``..._c2.log``). A
team's own firmware can still do this. Here the Python firmware of a ``tests.fault_rig.FaultRig``
(the acceptance filter of ``odocan firmware``'s board) is dead until ``Backlog.start_tick``
(halted, its receive path drained: a process not yet started hears nothing), a new firmware
opens its bus then and runs its first tick ``first_tick`` with every frame queued since
(``FirmwareBoard.run_tick``: a board that never ran hands them all to its receive ISR)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import can

from odocan.firmware import frames as fr
from odocan.sim.realtime import accepted_ids
from odocan.sim.robot import load
from odocan.sim.scenarios import get_scenario
from tests.fault_rig import FaultRig
from tests.fw_watch import Watch, watched


@dataclass(frozen=True)
class Backlog:
    """The firmware dead in ticks [kill_tick, start_tick) (none heard), its bus open from
    ``start_tick`` and its first tick at ``first_tick``."""

    kill_tick: int
    start_tick: int
    first_tick: int


# b5's shape: a firmware killed at 3.0 s, a new process's bus open at 4.0 s, its first tick
# at 4.7 s (70 encoder frames queued, 32 kept); c2's: the recorder started first, the
# firmware's bus open at 0.24 s, its first tick at 0.71 s (47 queued, 32 kept: primed on frame
# 24 of the log, named frame 55).
REBOOT = Backlog(300, 400, 470)
POWER_UP = Backlog(0, 24, 71)


def backlog_drive(log: Path, backlog: Backlog, robot: str = "pmir", scenario: str = "circle",
                  duration_s: float = 8.0, seed: int = 1) -> Watch:
    """Record the drive (module docstring) into the candump ``log``; the watch of the Python
    firmware's every step (``tests.fw_watch``)."""
    profile = load(robot)
    with watched(robot) as watch, can.Logger(str(log)) as out, FaultRig(
            robot=robot, seed=seed,
            scenario=get_scenario(scenario, profile, duration_s=duration_s)) as rig:
        def record(_k: int, frames: list[can.Message]) -> None:
            for msg in frames:
                out.on_message_received(msg)

        def dead_then_open(k: int) -> None:
            if backlog.kill_tick <= k < backlog.start_tick:  # no process: nothing heard
                while rig.board.bus.recv(0) is not None:
                    pass
            if k == backlog.start_tick:
                rig.board.reboot()  # the new process's firmware: RAM fresh, its bus open

        rig.board.accept_ids = accepted_ids("ODOM_MCU")  # as ``odocan firmware``'s board
        rig.observers.append(record)
        rig.before_board.append(dead_then_open)
        rig.halted = lambda k: backlog.kill_tick <= k < backlog.first_tick
        rig.run(duration_s)
    return watch


def first_tick_late(src: Path, dst: Path, first_s: float, late_s: float = 0.0127) -> int:
    """Copy ``src`` to ``dst`` with every firmware frame of the tick at ``first_s`` but its
    ODOM_POSE_X sent ``late_s`` later, the log kept in time order: how many frames moved. b5's
    first tick, 79 frames drained on a loaded machine, sent its Y half, twist and summary
    17.7 ms after its X, 14.6 ms before its next tick's (32.3 ms after the X); the lockstep's
    next tick comes 20 ms after the X, so 12.7 ms: more than a 10 ms cycle after the X, 7.3 ms
    before the next tick (closer, the two ticks read as one queued burst)."""
    ids = {fr.ODOM_POSE_Y_ID, fr.ODOM_TWIST_ID, fr.ODOM_STATUS_ID, fr.MOTOR_CMD_ID,
           fr.NAV_STATUS_ID}
    with can.LogReader(str(src)) as reader:
        msgs = list(reader)
    moved = 0
    for msg in msgs:
        if msg.arbitration_id in ids and abs(msg.timestamp - first_s) < 0.005:
            msg.timestamp += late_s
            moved += 1
    msgs.sort(key=lambda m: m.timestamp)
    with can.Logger(str(dst)) as out:
        for msg in msgs:
            out.on_message_received(msg)
    return moved
