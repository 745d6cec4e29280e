"""The firmware's board: its HAL implemented on a python-can bus and a clock.

The bus plays the MCU's CAN controller (11-bit data frames only: error, remote and extended frames
never reach the firmware's mailbox, as a hardware acceptance filter would drop them, nor frames
outside ``accept_ids`` when it is given); the caller's
periodic loop plays its timer and calls ``run_tick`` every ``TICK_PERIOD_US``.
"""

from __future__ import annotations

import can

from odocan.firmware.config import RobotParams
from odocan.firmware.ecu import OdomEcu
from odocan.firmware.hal import TICK_PERIOD_US
from odocan.sim.clock import Clock
from odocan.sim.node import BusNode

TICK_S = TICK_PERIOD_US / 1e6
TX_LATENCY_S = 0.001  # the firmware's frames leave 1 ms after the tick that made them


class FirmwareBoard(BusNode):
    """An ``OdomEcu`` on a python-can bus: receive ISR from ``recv``, transmit with ``send``."""

    def __init__(
        self,
        bus: can.BusABC,
        params: RobotParams,
        clock: Clock,
        accept_ids: frozenset[int] | None = None,
    ) -> None:
        """``accept_ids``: the acceptance filter's IDs (None: every 11-bit data frame)."""
        super().__init__(bus, clock)
        self.accept_ids = accept_ids
        self.ecu = OdomEcu(self, params)
        self._bus_off = False
        self.frames_dropped_by_filter = 0

    tx_latency_s = TX_LATENCY_S

    def transmit(self, can_id: int, data: bytes) -> bool:
        """The HAL's transmit (``firmware.hal.CanTx``)."""
        return self.send_frame(can_id, data)

    def service_rx(self) -> None:
        """Deliver every frame waiting on the bus to the firmware's receive ISR."""
        recv = self.bus.recv
        isr = self.ecu.isr_can_rx
        accept = self.accept_ids
        msg = recv(0)
        while msg is not None:
            if (
                msg.is_error_frame
                or msg.is_remote_frame
                or msg.is_extended_id
                or (accept is not None and msg.arbitration_id not in accept)
            ):
                self.frames_dropped_by_filter += 1
            else:
                isr(msg.arbitration_id, bytes(msg.data))
            msg = recv(0)

    def run_tick(self) -> None:
        """One timer period: the pending interrupts (status, receive), then the firmware's tick."""
        self._service_bus_state()
        self.service_rx()
        self.ecu.tick()

    def _service_bus_state(self) -> None:
        """The controller's status interrupt: report entering and leaving bus-off."""
        bus_off = self.bus.state is can.BusState.ERROR
        if bus_off != self._bus_off:
            self._bus_off = bus_off
            self.ecu.isr_bus_state(bus_off)
