"""The ECU's health: its state (INIT / OK / DEGRADED / FAULT), why, and the watchdog.

DEGRADED always carries a ``Reason`` (ODOM_STATUS ``REASON``): ENCODER_TIMEOUT (no accepted
WHEEL_ENCODERS for ``WATCHDOG_TICKS`` periods), TIME_LOST (a tick released that late),
MAILBOX_OVERFLOW (a received frame was dropped), IMPLAUSIBLE_STEP or COUNTER_RESET (both from
``firmware.encoders``). ``RECOVERY_FRAMES`` accepted encoder frames in a row with no new cause
bring it back to OK, but never before an ODOM_STATUS summary page has carried the episode
(DEGRADED and its reason) onto the bus: recovery takes 50 ms and the summary comes every 100 ms,
so without this hold a short episode would only ever show in the sticky ERROR_MASK. The motion
between the last frame before a counter restart and the first after it is unknowable, so
COUNTER_RESET stays until the host sets the pose again (ODOM_SET_POSE APPLY): no later cause
replaces it as the reason. POSE_UNCERTAIN (``firmware.uncertainty``: the merged steps' worst-case
error past its tolerance) is latched the same way. The set-pose releases the latch: the reason
stays, DEGRADED never goes out with REASON NONE (the DBC's "NONE while OK"), and recovers as any
other (the watchdog, usually in the set-pose's own tick), or a later cause replaces it. Errors
are state, never exceptions: each cause also sets its sticky bit in the u32 error mask.
"""

from __future__ import annotations

from odocan.firmware.clock import WATCHDOG_TICKS, FirmwareClock
from odocan.firmware.errors import ErrorFlag, ErrorMask, Reason, State

RECOVERY_FRAMES = 5  # accepted encoder frames in a row to leave DEGRADED
# The enumerators as module constants (C: the enumerators themselves): in CPython 3.11 a
# ``State.OK`` attribute read costs ~0.14 us, a global ~0.01 us; the watchdog reads several a tick.
_INIT = State.INIT
_OK = State.OK
_DEGRADED = State.DEGRADED
_FAULT = State.FAULT
_COUNTER_RESET = Reason.COUNTER_RESET
_POSE_UNCERTAIN = Reason.POSE_UNCERTAIN
_ENCODER_TIMEOUT = Reason.ENCODER_TIMEOUT


class Health:
    """State, reason and the watchdog's recovery count (C: two enums, a u8 and a u32)."""

    __slots__ = (
        "_clock",
        "_overflows_seen",
        "_reason_tick",
        "_released",
        "_unreported",
        "errors",
        "good_in_a_row",
        "overflows_before",
        "reason",
        "state",
    )

    def __init__(self, errors: ErrorMask, clock: FirmwareClock) -> None:
        self.errors = errors
        self._clock = clock
        self.state = _INIT
        self.reason = Reason.NONE
        self.good_in_a_row = 0  # accepted encoder frames since the last cause (<= RECOVERY_FRAMES)
        self._reason_tick = 0  # u32: the tick that set ``reason``
        self._released = False  # bool: a set-pose released the latched ``reason``
        self._unreported = False  # bool: no summary page has carried the last cause yet
        self._overflows_seen = 0  # u32: the mailbox's overflow count at the previous tick
        # u32: the mailbox's overflow count as of the previous tick's start (the count
        # ``_overflows_seen`` held before this tick's). Frames dropped by then came after every
        # frame the previous tick drained (a full ring drops the newest). A field, not a
        # property: the encoder input reads it on every frame.
        self.overflows_before = 0

    def config_fault(self) -> None:
        """The configuration is invalid: FAULT (CONFIG_INVALID) until a valid one is applied."""
        self.errors.set(ErrorFlag.CONFIG_INVALID)
        self.state = _FAULT
        self.reason = Reason.CONFIG_INVALID
        self._released = False

    def config_applied(self) -> None:
        """A valid configuration was applied: FAULT -> INIT (the next encoder frame: OK)."""
        if self.state is _FAULT:
            self.state = _INIT
            self.reason = Reason.NONE
            self._released = False

    def pose_set(self) -> None:
        """The host set the pose again (ODOM_SET_POSE APPLY): COUNTER_RESET and POSE_UNCERTAIN
        may now recover. The reason stays until then (cleared with the state by the watchdog):
        a DEGRADED summary always carries its REASON."""
        if self.reason is _COUNTER_RESET or self.reason is _POSE_UNCERTAIN:
            self._released = True

    def _latched(self) -> bool:
        """``reason`` is COUNTER_RESET or POSE_UNCERTAIN and no set-pose released it since."""
        return (
            self.reason is _COUNTER_RESET or self.reason is _POSE_UNCERTAIN
        ) and not self._released

    def degrade(self, reason: Reason) -> None:
        """OK or DEGRADED -> DEGRADED for ``reason`` (INIT and FAULT stay); recovery restarts.
        COUNTER_RESET is never replaced by a later cause, POSE_UNCERTAIN only by COUNTER_RESET
        (the others still set their error bits): only ODOM_SET_POSE APPLY releases them, or a
        later cause would let the firmware report OK on a pose that lost its continuity or its
        accuracy."""
        if self.state is _OK or self.state is _DEGRADED:
            self.state = _DEGRADED
            kept = self.reason
            if self._released or (kept is not _COUNTER_RESET and (
                kept is not _POSE_UNCERTAIN or reason is _COUNTER_RESET
            )):
                self.reason = reason
                self._released = False
            self.good_in_a_row = 0
            self._reason_tick = self._clock.ticks
            self._unreported = True

    def summary_sent(self, carried: bool) -> None:
        """An ODOM_STATUS summary page was handed to the driver (``carried``: it took the frame)
        with the current state and reason: a DEGRADED episode it carried may now recover."""
        if carried and self.state is _DEGRADED:
            self._unreported = False

    def pose_uncertain(self) -> None:
        """The pose's uncertainty passed its tolerance: POSE_UNCERTAIN, DEGRADED, latched until
        a set-pose (once: a latched episode is not restarted by every later merged step)."""
        self.errors.set(ErrorFlag.POSE_UNCERTAIN)
        if self.reason is not _POSE_UNCERTAIN or self._released:
            self.degrade(_POSE_UNCERTAIN)

    def time_lost(self) -> None:
        """This tick was released ``LOST_TIME_PERIODS`` or more late: TIME_LOST, DEGRADED."""
        self.errors.set(ErrorFlag.TIME_LOST)
        self.degrade(Reason.TIME_LOST)

    def check_overflows(self, overflows: int) -> None:
        """Frames the receive ISR dropped since the previous tick (``overflows``: the mailbox's
        u32 count): DEGRADED (MAILBOX_OVERFLOW)."""
        self.overflows_before = self._overflows_seen
        if overflows != self._overflows_seen:
            self._overflows_seen = overflows
            self.degrade(Reason.MAILBOX_OVERFLOW)

    def encoder_accepted(self) -> None:
        """An accepted WHEEL_ENCODERS frame: one more toward recovery; the first leaves INIT."""
        if self.good_in_a_row < RECOVERY_FRAMES:
            self.good_in_a_row += 1
        if self.state is _INIT:
            self.state = _OK

    def watchdog(self, periods_since_encoder: int) -> None:
        """Step 6. Encoders silent for WATCHDOG_TICKS periods of firmware time -> DEGRADED; back
        to OK after RECOVERY_FRAMES accepted frames with no new cause, once a summary page has
        carried the episode."""
        if self.state is _INIT or self.state is _FAULT:
            return
        if periods_since_encoder >= WATCHDOG_TICKS:
            self.errors.set(ErrorFlag.ENCODER_TIMEOUT)
            if self.state is _OK or (  # a cause raised in this very tick is kept
                self.reason is not _ENCODER_TIMEOUT and self._reason_tick != self._clock.ticks
            ):
                self.degrade(_ENCODER_TIMEOUT)
            self.good_in_a_row = 0
        elif (
            self.state is _DEGRADED
            and self.good_in_a_row >= RECOVERY_FRAMES
            and not self._latched()  # the pose lost its continuity or its accuracy
            and not self._unreported  # the bus has seen DEGRADED and why
        ):
            self.state = _OK
            self.reason = Reason.NONE
            self._released = False
