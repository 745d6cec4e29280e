"""``BusNode``: what every simulated node shares — a bus handle, a clock, counted sends."""

from __future__ import annotations

import can

from odocan.sim.clock import Clock
from odocan.sim.transport import data_frame


class BusNode:
    """A node on a python-can bus whose frames are stamped by its clock (+ ``tx_latency_s``)."""

    tx_latency_s = 0.0

    def __init__(self, bus: can.BusABC, clock: Clock) -> None:
        self.bus = bus
        self.clock = clock
        self.frames_sent = 0
        self.tx_errors = 0  # frames the bus refused (CanError)

    def send_frame(self, can_id: int, data: bytes) -> bool:
        """Send one classic data frame stamped now; False (and counted) when the bus refuses."""
        msg = data_frame(self.clock.now_s() + self.tx_latency_s, can_id, data)
        try:
            self.bus.send(msg)
        except can.CanError:
            self.tx_errors += 1
            return False
        self.frames_sent += 1
        return True
