"""``BusNode``: what every simulated node shares — a bus handle, a clock, counted sends."""

from __future__ import annotations

import can

from odocan.sim.clock import Clock
from odocan.sim.transport import OdocanBus, data_frame


class BusNode:
    """A node on a python-can bus whose frames are stamped by its clock (+ ``tx_latency_s``)."""

    tx_latency_s = 0.0

    def __init__(self, bus: can.BusABC, clock: Clock) -> None:
        self.bus = bus
        self.clock = clock
        self.frames_sent = 0
        self.tx_errors = 0  # frames the bus refused (CanError)

    def send_frame(self, can_id: int, data: bytes) -> bool:
        """Send one classic data frame stamped now; False (and counted) when the bus refuses.

        The lean transport takes the frame's fields (``OdocanBus.send_data``: no Message built
        for the sender only to be copied for each receiver); any other bus (python-can's, a
        fault injector, a wrapper put in ``self.bus``) a ``can.Message``."""
        stamp_s = self.clock.now_s() + self.tx_latency_s
        bus = self.bus
        try:
            if type(bus) is OdocanBus:
                bus.send_data(can_id, data, stamp_s)
            else:
                bus.send(data_frame(stamp_s, can_id, data))
        except can.CanError:
            self.tx_errors += 1
            return False
        self.frames_sent += 1
        return True
