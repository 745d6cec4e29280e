"""The firmware's hardware abstraction layer: all it knows of the world.

The firmware never reads a clock or a bus itself. A board support package (``sim.board`` in this
project; a CAN driver and a timer on a real MCU) implements ``CanTx`` and calls into the firmware:

* ``OdomEcu.isr_can_rx(can_id, data)`` from the CAN receive interrupt: copies the frame into a
  bounded mailbox and returns (ISR context: no allocation beyond the slot, no processing);
* ``OdomEcu.tick(now_us)`` from a periodic timer every ``TICK_PERIOD_US`` microseconds (thread
  context), ``now_us`` the free-running u32 microsecond timer at its release (the firmware's clock:
  a late or stalled tick is lost time, not one period);
* ``OdomEcu.isr_rx_overrun()`` when the CAN controller's receive FIFO overran;
* ``OdomEcu.isr_bus_state(bus_off)`` when the CAN controller enters or leaves bus-off.

With SecOC (docs/secoc.md), the board also gives the firmware, at start, its key (configuration,
never on the bus) and a ``FreshnessNvm``: one u32 cell of data flash or EEPROM holding EPOCH,
which survives a reboot.
"""

from __future__ import annotations

from typing import Protocol

TICK_PERIOD_US = 10_000  # the periodic tick: 100 Hz, the WHEEL_ENCODERS cycle
MAILBOX_SLOTS = 32  # receive mailbox depth (frames)


class CanTx(Protocol):
    """Transmit side of the CAN driver."""

    def transmit(self, can_id: int, data: bytes) -> bool:
        """Queue one classic CAN data frame (11-bit ID, 8 bytes). False when the TX queue is full
        or the controller is bus-off: the frame is dropped and the firmware counts it."""
        ...


class FreshnessNvm(Protocol):
    """The non-volatile cell holding the SecOC EPOCH (a u32 in data flash or EEPROM)."""

    def read_epoch(self) -> int:
        """The stored EPOCH (u32); 0 when the cell was never written."""
        ...

    def write_epoch(self, epoch: int) -> bool:
        """Store ``epoch`` (u32); False when the write failed (the firmware then fails closed)."""
        ...
