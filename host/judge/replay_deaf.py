"""The replayed firmware's CAN controller in bus-off (``host.judge.replay``'s board handle).

A bus-off (``replay_sent.bus_off_silences``) leaves the MCU ticking with a controller that
neither hears nor sends: in the recording rig its frames were refused (``sim.faults``: the
driver's send fails, ``sim.node.send_frame`` counts it, the firmware's ``tx_dropped`` too) and
none reached the log. The replay used to drain the board's receive queue alone: its firmware went
on putting poses, twists and status pages on the replayed bus for the whole bus-off. The judge
of the replayed bus then read poses inside a gap the recording bus never had: kobuki random 516,
10 s, ``busoff=4.0:0.3``, replayed step for step identical to the log, FAILed at 0.1003 mm
against its reference (the gap's allowance lost to the poses in it: 0.1 mm where the log's own
judge allowed 0.3567 mm). ``DeafBus`` is that controller: while ``deaf`` its ``state`` is
``ERROR`` (the board's status interrupt says bus-off, and bus-on again after, as
``sim.board.FirmwareBoard._service_bus_state`` reads it), every frame sent raises
``can.CanOperationError`` and every frame received is lost.
"""

from __future__ import annotations

import can


class DeafBus(can.BusABC):
    """A python-can handle over ``bus`` that is bus-off while ``deaf`` (module docstring)."""

    def __init__(self, bus: can.BusABC) -> None:
        self._bus = bus
        self.deaf = False
        super().__init__(channel=bus.channel_info)

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        """Send ``msg`` on the wrapped bus; refused while ``deaf``."""
        if self.deaf:
            raise can.CanOperationError("bus-off: frame not sent")
        self._bus.send(msg, timeout)

    def _recv_internal(self, timeout: float | None) -> tuple[can.Message | None, bool]:
        """The wrapped bus's next frame; while ``deaf`` every waiting frame is lost, none taken."""
        if self.deaf:
            while self._bus.recv(0) is not None:
                pass
            return None, False
        return self._bus.recv(timeout), False

    @property
    def state(self) -> can.BusState:
        """``ERROR`` (bus-off) while ``deaf``, else the wrapped bus's."""
        return can.BusState.ERROR if self.deaf else self._bus.state

    @state.setter
    def state(self, new_state: can.BusState) -> None:
        self._bus.state = new_state
