"""The ECU's transmit side: each message's E2E COUNTER, and frames the driver refused.

Every frame the firmware sends goes through ``Transmitter.send``, so a refused frame (TX queue
full, bus-off: ``CanTx.transmit`` returned False) is counted in one place (``tx_dropped``, u32
wrapping). Each message keeps its own 4-bit E2E COUNTER, advanced per frame sent.
"""

from __future__ import annotations

from odocan.firmware.e2e import COUNTER_MASK
from odocan.firmware.fixmath import wrap_u32
from odocan.firmware.hal import CanTx


class Transmitter:
    """The HAL's ``CanTx`` with the per-message counters (C: a u8 per transmitted message)."""

    __slots__ = ("_counters", "_hal", "tx_dropped")

    def __init__(self, hal: CanTx) -> None:
        self._hal = hal
        self._counters: dict[int, int] = {}
        self.tx_dropped = 0  # u32: the driver refused a frame

    def next_counter(self, can_id: int) -> int:
        """The E2E COUNTER (u4) of the next frame of ``can_id``: 0 first, then +1 mod 16."""
        counter = self._counters.get(can_id, -1)
        counter = (counter + 1) & COUNTER_MASK
        self._counters[can_id] = counter
        return counter

    def send(self, can_id: int, data: bytes) -> bool:
        """Hand one frame to the driver; count it when refused. True: the driver took it."""
        if self._hal.transmit(can_id, data):
            return True
        self.tx_dropped = wrap_u32(self.tx_dropped + 1)
        return False
