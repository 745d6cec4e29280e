"""The bus-off model: ISO 11898-1 fault confinement of one CAN controller, and its episodes.

``ErrorCounters`` holds TEC and REC and the error states; ``BusOffEpisode`` drives one
``busoff=T:DUR`` episode of a ``FaultSpec`` on them: at T the controller's automatic
retransmissions all fail (TEC +8 each, through the warning and error-passive limits, beyond 255:
bus-off), and DUR s later plus 128 x 11 recessive bits (at the bitrate) it recovers.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable

from can import BusState

from odocan.sim.faultspec import BusOff

LOG = logging.getLogger("odocan.faults")

DEFAULT_BITRATE = 500_000  # bit/s: the recovery time of bus-off (128 x 11 recessive bits)


class ErrorCounters:
    """ISO 11898-1 fault confinement of one CAN controller: TEC, REC and the error states.

    A transmit error adds 8 to TEC, a successful transmission takes 1 off; a receive error adds 1
    to REC, a successful reception takes 1 off (from above 127 it drops to 127). Error warning from
    96, error passive from 128, bus-off when TEC exceeds 255; bus-off is left only by ``recover``
    (after 128 occurrences of 11 recessive bits), which clears both counters.
    """

    WARNING_LIMIT = 96
    PASSIVE_LIMIT = 128
    BUS_OFF_LIMIT = 255
    RECOVERY_BITS = 128 * 11

    def __init__(self) -> None:
        self.tec = 0
        self.rec = 0
        self.bus_off = False

    def transmit_error(self) -> None:
        """A transmitter saw an error: TEC += 8 (bus-off beyond 255)."""
        if not self.bus_off:
            self.tec += 8
            self.bus_off = self.tec > self.BUS_OFF_LIMIT

    def transmit_success(self) -> None:
        """A frame went out: TEC -= 1."""
        if not self.bus_off and self.tec:
            self.tec -= 1

    def receive_error(self) -> None:
        """A receiver saw an error: REC += 1 (held at 255)."""
        if not self.bus_off:
            self.rec = min(self.rec + 1, 255)

    def receive_success(self) -> None:
        """A frame came in: REC -= 1, or back to 127 from error-passive levels."""
        if self.rec > 127:
            self.rec = 127
        elif self.rec:
            self.rec -= 1

    def recover(self) -> None:
        """128 x 11 recessive bits seen while bus-off: error active, TEC = REC = 0."""
        self.tec = self.rec = 0
        self.bus_off = False

    @property
    def error_warning(self) -> bool:
        """TEC or REC at the warning limit (96) or above."""
        return self.tec >= self.WARNING_LIMIT or self.rec >= self.WARNING_LIMIT

    @property
    def bus_state(self) -> BusState:
        """ACTIVE (error active), PASSIVE (error passive) or ERROR (bus-off)."""
        if self.bus_off:
            return BusState.ERROR
        if self.tec >= self.PASSIVE_LIMIT or self.rec >= self.PASSIVE_LIMIT:
            return BusState.PASSIVE
        return BusState.ACTIVE


class BusOffEpisode:
    """One ``busoff=T:DUR`` episode on a controller's ``counters``.

    Args:
        episode: when and how long (None: the controller never goes bus-off).
        counters: the controller's error counters (changed in place).
        recovery_s: the time of 128 x 11 recessive bits at the bus's bitrate (s).
        on_bus_off: called with (time s, TEC) when the climb reaches bus-off.

    ``recovered_at_s`` is the instant the controller left bus-off (T + DUR + the 128 x 11 bits),
    however late ``advance_to`` learns it: frames it held meanwhile reach the bus then.
    """

    def __init__(
        self,
        episode: BusOff | None,
        counters: ErrorCounters,
        recovery_s: float,
        on_bus_off: Callable[[float, int], None],
    ) -> None:
        self._episode = episode
        self._counters = counters
        self._recovery_s = recovery_s
        self._on_bus_off = on_bus_off
        self._started = False
        self._recover_at_s = math.inf
        self.recovered_at_s = -math.inf  # when the controller left bus-off (-inf: not yet)

    def advance_to(self, now_s: float) -> None:
        """Bus-off transitions up to ``now_s`` (s): the climb at T, the recovery after it."""
        episode = self._episode
        if episode is None:
            return
        if not self._started and now_s >= episode.at_s:
            self._started = True
            self._climb(episode.at_s)
            self._recover_at_s = episode.at_s + episode.duration_s + self._recovery_s
        if self._counters.bus_off and now_s >= self._recover_at_s:
            self._counters.recover()
            self.recovered_at_s = self._recover_at_s
            LOG.info("busoff recovered t=%.6f: 128 x 11 recessive bits, TEC = REC = 0", now_s)

    def _climb(self, at_s: float) -> None:
        """The controller's automatic retransmissions all fail: TEC +8 each, to beyond 255."""
        c = self._counters
        while not c.bus_off:
            was_warning, was_state = c.error_warning, c.bus_state
            c.transmit_error()
            if c.error_warning and not was_warning:
                LOG.info("busoff climb t=%.6f: TEC %d, error warning", at_s, c.tec)
            if c.bus_state is not was_state and not c.bus_off:
                LOG.info("busoff climb t=%.6f: TEC %d, error passive", at_s, c.tec)
        self._on_bus_off(at_s, c.tec)


__all__ = ["DEFAULT_BITRATE", "BusOffEpisode", "ErrorCounters"]
