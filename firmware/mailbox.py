"""The receive mailbox: the only thing the CAN receive ISR touches (sample, then compute).

``Mailbox`` is a fixed ring of ``MAILBOX_SLOTS`` frames (C: two arrays and two u8 indices, no
allocation). The ISR puts, the tick drains in arrival order; a full mailbox drops the frame and
counts it (``overflows``, u32 wrapping), which the health monitor turns into DEGRADED
(MAILBOX_OVERFLOW) at the next tick.
"""

from __future__ import annotations

from odocan.firmware.fixmath import wrap_u32
from odocan.firmware.hal import MAILBOX_SLOTS


class Mailbox:
    """A fixed-size ring of received frames (``MAILBOX_SLOTS``); a full mailbox drops and counts."""

    __slots__ = ("_data", "_head", "_ids", "count", "overflows")

    def __init__(self) -> None:
        self._ids = [0] * MAILBOX_SLOTS
        self._data = [b""] * MAILBOX_SLOTS
        self._head = 0
        self.count = 0  # u8: frames held (the tick drains while it is non-zero)
        self.overflows = 0  # u32, wrapping

    def put(self, can_id: int, data: bytes) -> bool:
        """ISR context: store one frame, or count an overflow. No allocation."""
        if self.count == MAILBOX_SLOTS:
            self.overflows = wrap_u32(self.overflows + 1)
            return False
        slot = (self._head + self.count) % MAILBOX_SLOTS
        self._ids[slot] = can_id
        self._data[slot] = data
        self.count += 1
        return True

    def count_overrun(self) -> None:
        """ISR context: the CAN controller's FIFO overran (one event, however many frames)."""
        self.overflows = wrap_u32(self.overflows + 1)

    def get(self) -> tuple[int, bytes]:
        """Thread context: the oldest frame; only while ``count`` is non-zero (the drain's loop
        tests it, as C's ``while (count != 0u)``: no test here, no None to return)."""
        slot = self._head
        self._head = (slot + 1) % MAILBOX_SLOTS
        self.count -= 1
        return self._ids[slot], self._data[slot]
