"""A motor controller that pauses and then floods its backlog (issue #11, an outside trial:
``odocan sim`` SIGSTOPped 3 s then continued sends the ~300 frames it skipped back to back).

``paused_drive`` runs pmir in lockstep (``tests.fault_rig.FaultRig``) with the simulator's
frames held from tick ``pause_at`` for ``paused`` ticks (its node runs on: the vehicle moves and
samples its encoders as a process catching up would) and let out together in the tick after,
``BURST_GAP_S`` apart, so that the firmware's 32-slot mailbox keeps the first 32 and drops the
rest. Its frames (sim and firmware) as the host heard them, in bus order.
"""

from __future__ import annotations

from functools import cache
from typing import Any

import can

from odocan.sim.board import TICK_S
from odocan.sim.robot import load
from odocan.sim.scenarios import get_scenario
from tests.fault_rig import FaultRig

PMIR = load("pmir")
BURST_GAP_S = 2e-6  # between two frames of the flood (a vcan flood: microseconds)


class _Holding:
    """The simulator's bus handle's ``send`` while paused: frames kept, let out later."""

    def __init__(self, bus: can.BusABC) -> None:
        self.bus, self.send_now = bus, bus.send
        self.held: list[can.Message] = []
        self.paused = False

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self.paused:
            self.held.append(msg)
        else:
            self.send_now(msg, timeout)

    def release(self, at_s: float) -> None:
        """The held frames, in order, stamped ``BURST_GAP_S`` apart from ``at_s``."""
        for k, msg in enumerate(self.held):
            msg.timestamp = at_s + k * BURST_GAP_S
            self.send_now(msg)
        self.held = []


@cache
def paused_drive(pause_at: int, paused: int, scenario: str = "circle", run_s: float = 10.0,
                 firmware: str = "python") -> tuple[can.Message, ...]:
    """``run_s`` of pmir on ``scenario``, the simulator's frames held in ticks
    ``pause_at`` .. ``pause_at + paused - 1`` and let out at the start of the next tick."""
    heard: list[can.Message] = []
    with FaultRig(scenario=get_scenario(scenario, PMIR, duration_s=60.0), firmware=firmware
                  ) as rig:
        holding = _Holding(rig.sim_bus)
        rig.sim_bus.send = holding.send  # type: ignore[method-assign]

        def pause(k: int) -> None:
            if k == pause_at:
                holding.paused = True
            elif k == pause_at + paused:
                holding.paused = False
                holding.release(k * TICK_S)

        rig.sim.tick = _before(rig.sim.tick, pause)  # type: ignore[method-assign]
        rig.observers.append(lambda _k, got: heard.extend(got))
        rig.run(run_s)
    return tuple(heard)


def _before(tick: Any, hook: Any) -> Any:
    def wrapped(k: int) -> None:
        hook(k)
        tick(k)
    return wrapped
