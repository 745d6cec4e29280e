"""The firmware's clock: 10 ms periods counted on the board's free-running microsecond timer.

``time_periods`` (u32, periods since reset) advances at the start of every tick by the periods
elapsed on the timer since the previous tick (``advance(now_us)``; without a timer, one period per
tick). Ticks run and time passed differ when the MCU stalls: a tick released ``LOST_TIME_PERIODS``
periods or more after the previous one has lost time (``time_lost_now``; the health monitor sets
TIME_LOST). UPTIME, the watchdog and the twist's dt all use this time; ``ticks`` (u32) counts the
ticks that ran and paces the scheduled transmissions.
"""

from __future__ import annotations

from odocan.firmware.fixmath import U32_MAX, wrap_u32
from odocan.firmware.hal import TICK_PERIOD_US

WATCHDOG_TICKS = 10  # 10 encoder periods without a fresh frame -> DEGRADED
LOST_TIME_PERIODS = WATCHDOG_TICKS  # a tick this many periods after the previous one: time lost
TICKS_PER_SECOND = 1_000_000 // TICK_PERIOD_US


class FirmwareClock:
    """Ticks run and periods passed (C: three u32, an i32 remainder and a bool)."""

    __slots__ = (
        "_timer_prev_us",
        "_timer_rest_us",
        "periods_lost",
        "ticks",
        "time_lost_now",
        "time_periods",
    )

    def __init__(self) -> None:
        self.ticks = 0  # u32 uptime in ticks
        self.time_periods = 0  # u32: 10 ms periods since reset, by the timer (ticks run or not)
        self._timer_prev_us: int | None = None  # u32 timer value at the previous tick
        self._timer_rest_us = 0  # i32, within +-TICK_PERIOD_US/2: time not yet counted
        self.periods_lost = 0  # u32: periods the firmware did not run (stalls)
        self.time_lost_now = False  # this tick came LOST_TIME_PERIODS periods or more late

    def advance(self, now_us: int | None) -> int:
        """Firmware time: the periods elapsed on the timer since the previous tick, returned;
        rounded, the remainder carried to the next tick so jitter never drifts the clock
        (u32 elapsed: the timer may wrap, every 71.6 min). ``now_us``: the u32 timer at this
        tick's release (None: no timer, one period has passed)."""
        periods = 1
        if now_us is not None:
            if self._timer_prev_us is not None:
                elapsed_us = ((now_us - self._timer_prev_us) & U32_MAX) + self._timer_rest_us
                periods = (elapsed_us + TICK_PERIOD_US // 2) // TICK_PERIOD_US
                self._timer_rest_us = elapsed_us - periods * TICK_PERIOD_US
            self._timer_prev_us = now_us & U32_MAX
        self.time_periods = (self.time_periods + periods) & U32_MAX  # (uint32_t)
        time_lost_now = periods >= LOST_TIME_PERIODS
        self.time_lost_now = time_lost_now
        if time_lost_now:
            self.periods_lost = wrap_u32(self.periods_lost + periods - 1)
        return periods

    def end_tick(self) -> None:
        """The tick is done: count it (u32, wrapping)."""
        self.ticks = (self.ticks + 1) & U32_MAX  # (uint32_t)

    def uptime_s(self) -> int:
        """Whole seconds of firmware time since reset (u32)."""
        return self.time_periods // TICKS_PER_SECOND
