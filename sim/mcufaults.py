"""The firmware MCU's own faults, tick by tick: ``--faults stall=T:DUR`` and ``reboot=T[:DUR]``.

A bus handle (``sim.faults.FaultInjectingBus``) can lose, hold or corrupt frames, but it cannot
halt or reset the microcontroller behind it; the rig that runs the board's ticks can. A halted
MCU is a board whose ``run_tick`` is not called: its CAN controller goes on receiving, and the
board's next ``run_tick`` finds the time lost and hands the firmware only what its hardware FIFO
held (``sim.board``: FIFO-locked, the rest overrun), exactly as after a SIGSTOP of a live
firmware. A reset is ``FirmwareBoard.reboot`` (a new firmware: RAM lost, INIT, priming on its
first encoder frame, the NVM cell kept) plus the receive FIFO emptied, as resetting the CAN
peripheral does; during the boot time nothing runs and the controller, not yet set up, takes no
frame. The rig (``sim.rig.LockstepRig``) and the tests' ``FaultRig`` both step the board through
``McuFaults``, so a stall or reboot of ``odocan run`` is the one the tests judge.

Episodes are in the rig's simulated time and fall on ticks: a tick k (its start at k x 10 ms) is
halted when T <= k x 10 ms < T + DUR; the reset happens at the start of the first tick at or
after T, before any node's frames of that tick, so the new firmware's first tick takes that
tick's encoder frame. Nothing here draws a random number: the same spec, the same ticks.
"""

from __future__ import annotations

import math

from odocan.sim.board import TICK_S, FirmwareBoard
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.faultspec import BusOff, FaultSpec, mcu_text


def tick_at(t_s: float) -> int:
    """The first tick starting at or after ``t_s`` (rounded to a microsecond first, so that
    3.0 s is tick 300, not 301 from 3.0 / 0.01 = 300.00000000000006)."""
    return math.ceil(round(t_s / TICK_S, 6))


def _ticks(episode: BusOff | None) -> range:
    """The ticks starting within [at_s, at_s + duration_s)."""
    if episode is None:
        return range(0)
    return range(tick_at(episode.at_s), tick_at(episode.at_s + episode.duration_s))


class McuFaults:
    """The stall and reboot of a ``FaultSpec`` applied to a board, tick by tick.

    Call ``before_nodes(board, k)`` at the start of tick k (before any node sends) and run the
    board's tick only when ``runs(k)``."""

    def __init__(self, spec: FaultSpec) -> None:
        self.halted = _ticks(spec.stall)
        self.reset_tick = None if spec.reboot is None else tick_at(spec.reboot.at_s)
        self.booting = _ticks(spec.reboot)  # from the reset: no tick, no frame taken
        # Spans whose frames the controller never takes: the reset and its boot time; and a
        # stall from the first tick, a late power-up (the firmware never ran to set the
        # controller up: as the tests' power-up delay, ``FaultRig.halted`` and a drained FIFO;
        # taken into the FIFO, its whole backlog reached a firmware that never ran, at once).
        self.dark: list[tuple[int, int]] = []  # (first, last): ticks its FIFO is emptied at
        if self.reset_tick is not None:
            self.dark.append((self.reset_tick, self.booting.stop))
        if self.halted and self.halted.start == 0:
            self.dark.append((0, self.halted.stop))
        self.frames_lost = 0  # frames the reset and the boot time took from the receive FIFO

    def before_nodes(self, board: FirmwareBoard, k: int) -> None:
        """At the start of tick ``k``: the reset when due (RAM lost), and while the MCU resets,
        boots or has not yet powered up, the frames its controller did not take (sent since
        its last tick) lost."""
        if k == self.reset_tick:
            board.reboot()
        if not any(first <= k <= last for first, last in self.dark):
            return
        while board.bus.recv(0) is not None:  # the reset empties the FIFO; booting, none taken
            self.frames_lost += 1

    def runs(self, k: int) -> bool:
        """True when the MCU runs its tick ``k`` (neither halted nor booting)."""
        return k not in self.halted and k not in self.booting


def mcu_faults(spec: FaultSpec | None) -> McuFaults | None:
    """The MCU's faults of ``spec`` (None when it asks for none)."""
    return McuFaults(spec) if spec is not None and spec.mcu_active else None


def check_within(spec: FaultSpec | None, run_s: float) -> None:
    """A stall or reboot that ends after the run's ``run_s`` seconds is refused in one line: a
    stall never resumed, or a reset the run never reaches, would be judged as no such fault (a
    CI job believing it tested a hang it never ran)."""
    if spec is None:
        return
    for key in ("stall", "reboot"):
        episode = getattr(spec, key)
        if episode is not None and episode.at_s + episode.duration_s >= run_s:
            shape = "T + DUR" if episode.duration_s else "T"
            raise ConfigurationError(
                f"faults: {mcu_text(spec, key)}: {shape} must be before "
                f"the run's end ({run_s:g} s; --duration)")
