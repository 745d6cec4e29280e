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
tick's encoder frame. A run may have any number of stalls and reboots, in time order, the
firmware running at least one tick between two (a watchdog's reset may come at the tick a halt
ends). Nothing here draws a random number: the same spec, the same ticks.
"""

from __future__ import annotations

import bisect
import itertools
import math

from odocan.sim.board import TICK_S, FirmwareBoard
from odocan.sim.exceptions import ConfigurationError
from odocan.sim.faultspec import BusOff, FaultSpec, mcu_episodes, mcu_text


def tick_at(t_s: float) -> int:
    """The first tick starting at or after ``t_s`` (rounded to a microsecond first, so that
    3.0 s is tick 300, not 301 from 3.0 / 0.01 = 300.00000000000006)."""
    return math.ceil(round(t_s / TICK_S, 6))


def _ticks(episode: BusOff) -> range:
    """The ticks starting within [at_s, at_s + duration_s)."""
    return range(tick_at(episode.at_s), tick_at(episode.at_s + episode.duration_s))


class McuFaults:
    """The stalls and reboots of a ``FaultSpec`` applied to a board, tick by tick.

    Call ``before_nodes(board, k)`` at the start of tick k (before any node sends) and run the
    board's tick only when ``runs(k)``."""

    def __init__(self, spec: FaultSpec) -> None:
        _check_apart(spec)
        self.halted = [_ticks(stall) for stall in spec.stalls]
        self.reset_ticks = {tick_at(reboot.at_s) for reboot in spec.reboots}
        self.booting = [_ticks(reboot) for reboot in spec.reboots]  # no tick, no frame taken
        # Spans whose frames the controller never takes: each reset and its boot time; and a
        # stall from the first tick, a late power-up (the firmware never ran to set the
        # controller up: as the tests' power-up delay, ``FaultRig.halted`` and a drained FIFO;
        # taken into the FIFO, its whole backlog reached a firmware that never ran, at once).
        self.dark: list[tuple[int, int]] = []  # (first, last): ticks its FIFO is emptied at
        self.dark += [(tick_at(r.at_s), boot.stop) for r, boot in zip(spec.reboots, self.booting,
                                                                     strict=True)]
        self.dark += [(0, halt.stop) for halt in self.halted if halt.start == 0]
        idle = sorted(self.halted + self.booting, key=lambda span: span.start)  # apart
        self._idle_starts, self._idle_stops = [s.start for s in idle], [s.stop for s in idle]
        self.frames_lost = 0  # frames the resets and the boot times took from the receive FIFO

    def before_nodes(self, board: FirmwareBoard, k: int) -> None:
        """At the start of tick ``k``: a reset when due (RAM lost), and while the MCU resets,
        boots or has not yet powered up, the frames its controller did not take (sent since
        its last tick) lost."""
        if k in self.reset_ticks:
            board.reboot()
        if not any(first <= k <= last for first, last in self.dark):
            return
        while board.bus.recv(0) is not None:  # the reset empties the FIFO; booting, none taken
            self.frames_lost += 1

    def runs(self, k: int) -> bool:
        """True when the MCU runs its tick ``k`` (neither halted nor booting)."""
        at = bisect.bisect_right(self._idle_starts, k) - 1  # the last span started by k
        return at < 0 or k >= self._idle_stops[at]


def _check_apart(spec: FaultSpec) -> None:
    """Episodes apart in seconds (``FaultSpec``) may still meet on the 10 ms ticks they fall on
    (``stall=2:1.004,stall=3.005:1``: one halt of ticks 200..400): refused in one line, as two
    episodes that would be judged as one. The firmware must run a tick between two (a reset
    may still come at the tick a halt ends: a watchdog's)."""
    pairs = mcu_episodes(spec)
    for (key, one), (then, other) in itertools.pairwise(pairs):
        resumes = tick_at(one.at_s + one.duration_s)  # its first tick run again
        watchdog = key == "stall" and then == "reboot"
        if tick_at(other.at_s) <= resumes - watchdog:
            raise ConfigurationError(
                f"faults: {mcu_text(key, one)} and {mcu_text(then, other)} fall on the same or "
                f"adjacent {TICK_S * 1000:g} ms ticks (the firmware runs none between them): "
                "give them apart")


def mcu_faults(spec: FaultSpec | None) -> McuFaults | None:
    """The MCU's faults of ``spec`` (None when it asks for none)."""
    return McuFaults(spec) if spec is not None and spec.mcu_active else None


def check_within(spec: FaultSpec | None, run_s: float) -> None:
    """A stall or reboot that ends after the run's last tick (``run_s`` seconds of 10 ms ticks)
    is refused in one line: a stall never resumed, or a reset the run never reaches, would be
    judged as no such fault (a CI job believing it tested a hang it never ran; an outside trial:
    ``reboot=9.991`` and ``stall=9.5:0.499`` of a 10 s run PASSed with no reboot or stall);
    so are a bus-off and a babble window that start after the last tick (``busoff=99:0.3`` of
    an 8 s run PASSed with no bus-off), and episodes that meet on the ticks
    (``_check_apart``)."""
    if spec is None:
        return
    ticks = tick_at(run_s)  # the run's ticks: 0 .. ticks - 1
    for key, window in (("busoff", spec.busoff), ("babble", spec.babble_window)):
        if window is not None and tick_at(window.at_s) >= ticks:  # never begins
            said = (mcu_text(key, window) if key == "busoff"  # babble=RATE:ID:T:DUR's end
                    else f"babble=...:{window.at_s:g}:{window.duration_s:g}")
            raise ConfigurationError(
                f"faults: {said}: T must fall on a tick of the run, the last at "
                f"{(ticks - 1) * TICK_S:.2f} s (--duration {run_s:g})")
    for key, episode in mcu_episodes(spec):
        if tick_at(episode.at_s + episode.duration_s) >= ticks:  # never reached or resumed
            shape = "T + DUR" if episode.duration_s else "T"
            raise ConfigurationError(
                f"faults: {mcu_text(key, episode)}: {shape} must fall on a tick of the run, "
                f"the last at {(ticks - 1) * TICK_S:.2f} s (--duration {run_s:g})")
    _check_apart(spec)
