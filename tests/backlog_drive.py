"""A lockstep drive whose new firmware's first tick integrates a backlog (issue #11: a FAIL
must never blame a correct firmware).

Before ``FirmwareBoard.join_bus`` an ``odocan firmware`` process opened its bus ~0.7 s before
its first tick: the new firmware's first tick got ~79 queued frames at once, its 32-slot mailbox
kept the oldest 32 and dropped the rest (``/work/findings/backlog_first_tick_b5.log``: the
first pose names the frame 32 frames before the newest of its ENC_COUNTER). A team's own
firmware can still do this. Here the Python firmware of a ``tests.fault_rig.FaultRig`` is
killed (halted, its receive path drained: a dead process hears nothing) at ``KILL_TICK``, a new
one starts at ``START_TICK`` with its bus open, and runs its first tick ``BACKLOG_TICKS`` later
with every frame queued since (``FirmwareBoard.run_tick``: a board that never ran hands them all
to the receive ISR)."""

from __future__ import annotations

from pathlib import Path

import can

from odocan.sim.realtime import accepted_ids
from odocan.sim.robot import load
from odocan.sim.scenarios import get_scenario
from tests.fault_rig import FaultRig
from tests.fw_watch import Watch, watched

KILL_TICK = 300  # the old firmware killed at 3.0 s
START_TICK = 400  # the new process opens its bus at 4.0 s
BACKLOG_TICKS = 70  # its first tick 0.7 s later (4.7 s): 70 encoder frames queued
FIRST_TICK_S = (START_TICK + BACKLOG_TICKS) * 0.01


def backlog_drive(log: Path, robot: str = "kobuki", scenario: str = "circle",
                  duration_s: float = 10.0, seed: int = 1) -> Watch:
    """Record the drive (module docstring) into the candump ``log``; the watch of the Python
    firmware's every step (``tests.fw_watch``)."""
    profile = load(robot)
    with watched(robot) as watch, can.Logger(str(log)) as out, FaultRig(
            robot=robot, seed=seed,
            scenario=get_scenario(scenario, profile, duration_s=duration_s)) as rig:
        def record(_k: int, frames: list[can.Message]) -> None:
            for msg in frames:
                out.on_message_received(msg)

        def kill_and_start(k: int) -> None:
            if KILL_TICK <= k < START_TICK:  # a dead process: its socket hears nothing
                while rig.board.bus.recv(0) is not None:
                    pass
            if k == START_TICK:
                rig.board.reboot()  # the new process's firmware: RAM fresh, bus open

        rig.board.accept_ids = accepted_ids("ODOM_MCU")  # as ``odocan firmware``'s board
        rig.observers.append(record)
        rig.before_board.append(kill_and_start)
        rig.halted = lambda k: KILL_TICK <= k < START_TICK + BACKLOG_TICKS
        rig.run(duration_s)
    return watch
