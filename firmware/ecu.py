"""The odometry ECU's main loop: a receive ISR, a bounded mailbox and a periodic tick.

Sample, then compute. ``isr_can_rx`` only copies a frame into the mailbox (overflows counted).
``tick`` runs every ``TICK_PERIOD_US``, in this fixed order:

1. drain the mailbox, in arrival order;
2. E2E check of each frame (Profile 2; a frame that fails never changes state);
3. odometry on every accepted WHEEL_ENCODERS frame; staged ODOM_SET_POSE / ODOM_CONFIG /
   NAV_GOAL writes, each answered by ODOM_ACK;
4. controllers: navigation (``firmware.nav``) every 20 ms, from the on-board pose;
5. scheduled transmissions at the DBC's cycle times: ODOM_POSE_X/Y and ODOM_TWIST every 20 ms,
   ODOM_STATUS every 100 ms (the summary page, then one rotating page of counts), MOTOR_CMD
   every 20 ms while navigating, NAV_STATUS every 100 ms and in the tick STATE or GOAL_ID changes;
6. the watchdog: no accepted WHEEL_ENCODERS for ``WATCHDOG_TICKS`` periods -> DEGRADED (integration
   paused, ENCODER_TIMEOUT set); ``RECOVERY_FRAMES`` accepted frames in a row -> OK again. The
   counters are absolute, so the first frame after a gap carries the distance driven meanwhile.

Time. The firmware's clock is ``time_periods`` (u32, 10 ms periods since reset), advanced at the
start of every tick by the periods elapsed on the board's free-running microsecond timer
(``tick(now_us)``; without a timer, one period per tick). Ticks run and time passed differ when
the MCU stalls: a tick released ``WATCHDOG_TICKS`` periods or more after the previous one sets
TIME_LOST and goes DEGRADED. UPTIME, the watchdog and the twist's dt all use this time.

DEGRADED always carries a ``Reason`` (ODOM_STATUS ``REASON``): ENCODER_TIMEOUT, TIME_LOST,
MAILBOX_OVERFLOW (a received frame was dropped), IMPLAUSIBLE_STEP (a step beyond
``max_wheel_speed_mm_s``, not integrated) or COUNTER_RESET (the encoder counters restarted: after
``RESYNC_FRAMES`` frames consistent with each other but not with the last accepted one, the
odometry is re-primed on the first of them; the jump itself is never integrated). The motion
between the last frame before a counter restart and the first after it is unknowable, so
COUNTER_RESET stays until the host sets the pose again (ODOM_SET_POSE APPLY): no later cause
replaces it as the reason.

SecOC (docs/secoc.md). A firmware provisioned with a key (``secoc_key``, configuration from the
board, never on the bus) holds each ODOM_SET_POSE, ODOM_CONFIG and NAV_GOAL frame that passed its
E2E check and acts on it only when the ODOM_AUTH that follows verifies (``firmware.secoc``);
otherwise it answers ODOM_ACK NACK with the AUTH reason (AUTH_FAILED, AUTH_FRESHNESS,
AUTH_MISSING after ``AUTH_TIMEOUT_TICKS``, AUTH_UNAVAILABLE). It sends ODOM_FRESHNESS at boot,
every second and after a refusal. EPOCH lives in the board's ``FreshnessNvm`` cell. Without a key
the firmware behaves as before SecOC (ODOM_AUTH is filtered, nothing extra is sent).
"""

from __future__ import annotations

from odocan.firmware import frames as fr
from odocan.firmware.config import (
    TWO_PI_Q60,
    ConfigReason,
    RobotParams,
    derive_constants,
    validate,
)
from odocan.firmware.e2e import COUNTER_MASK, E2EReceiver, E2EStatus
from odocan.firmware.errors import ErrorFlag, ErrorMask, Reason, State
from odocan.firmware.fixmath import (
    U16_MAX,
    U32_MAX,
    U64_MAX,
    div_round_i64,
    mul_shr_round_i64,
    muldiv_round_u64,
    sat_range,
    wrap_i16,
    wrap_i32,
    wrap_signed,
    wrap_u32,
)
from odocan.firmware.hal import MAILBOX_SLOTS, TICK_PERIOD_US, CanTx, FreshnessNvm
from odocan.firmware.nav import NAV_PERIOD_TICKS, Navigator
from odocan.firmware.odometry import Odometry
from odocan.firmware.secoc import (
    FRESHNESS_PERIOD_TICKS,
    AuthRequest,
    AuthStatus,
    FreshnessCause,
    Held,
    SecocReceiver,
    SecuredCommands,
)

ENCODER_PERIOD_US = 10_000  # WHEEL_ENCODERS GenMsgCycleTime
POSE_PERIOD_TICKS = 2  # ODOM_POSE_X/Y, ODOM_TWIST: 20 ms
STATUS_PERIOD_TICKS = 10  # ODOM_STATUS: 100 ms
WATCHDOG_TICKS = 10  # 10 encoder periods without a fresh frame -> DEGRADED
RECOVERY_FRAMES = 5  # accepted encoder frames in a row to leave DEGRADED
TICKS_PER_SECOND = 1_000_000 // TICK_PERIOD_US
LOST_TIME_PERIODS = WATCHDOG_TICKS  # a tick this many periods after the previous one: time lost
MAX_WHEEL_SPEED_MM_S = 4_000  # build-time maximum rim speed of either wheel (a #define)
RESYNC_FRAMES = 3  # frames consistent with each other, not with the last one: counters restarted
COUNTER_VALUES = 16  # E2E COUNTER values (4 bits): one whole counter cycle
STEP_PERIODS_MAX = U16_MAX  # the twist's dt and the plausibility bound saturate here (655 s)
TWIST_SUM_MAX = 1 << 32  # one tick's summed steps saturate at 4096 m (Q20) and 4 rad (Q30)
WIRE_COUNTER_BITS = 24  # WHEEL_ENCODERS carries the low 24 bits of each counter
_ROTATING_PAGES = (
    fr.StatusPage.FRAME_TOTALS,
    fr.StatusPage.E2E_WHEEL_ENCODERS,
    fr.StatusPage.E2E_ODOM_SET_POSE,
    fr.StatusPage.E2E_ODOM_CONFIG,
    fr.StatusPage.E2E_NAV_GOAL,
)
_CONFIG_FIELDS = {
    fr.ConfigParam.COUNTS_PER_REV: "counts_per_rev",
    fr.ConfigParam.WHEEL_RADIUS_LEFT: "wheel_radius_left_nm",
    fr.ConfigParam.WHEEL_RADIUS_RIGHT: "wheel_radius_right_nm",
    fr.ConfigParam.WHEELBASE: "wheelbase_nm",
    fr.ConfigParam.COUNTER_BITS: "counter_bits",
    fr.ConfigParam.INTEGRATOR: "integrator",
}


class Mailbox:
    """A fixed-size ring of received frames (``MAILBOX_SLOTS``); a full mailbox drops and counts."""

    __slots__ = ("_count", "_data", "_head", "_ids", "overflows")

    def __init__(self) -> None:
        self._ids = [0] * MAILBOX_SLOTS
        self._data = [b""] * MAILBOX_SLOTS
        self._head = 0
        self._count = 0
        self.overflows = 0  # u32, wrapping

    def put(self, can_id: int, data: bytes) -> bool:
        """ISR context: store one frame, or count an overflow. No allocation."""
        if self._count == MAILBOX_SLOTS:
            self.overflows = wrap_u32(self.overflows + 1)
            return False
        slot = (self._head + self._count) % MAILBOX_SLOTS
        self._ids[slot] = can_id
        self._data[slot] = data
        self._count += 1
        return True

    def get(self) -> tuple[int, bytes] | None:
        """Thread context: the oldest frame, or None when empty."""
        if self._count == 0:
            return None
        slot = self._head
        self._head = (slot + 1) % MAILBOX_SLOTS
        self._count -= 1
        return self._ids[slot], self._data[slot]


class OdomEcu:
    """The odometry ECU (node ``ODOM_MCU``)."""

    def __init__(
        self,
        hal: CanTx,
        params: RobotParams,
        max_wheel_speed_mm_s: int = MAX_WHEEL_SPEED_MM_S,
        *,
        secoc_key: bytes | None = None,
        nvm: FreshnessNvm | None = None,
    ) -> None:
        """``max_wheel_speed_mm_s``: the fastest rim speed either wheel can reach (u16 mm/s); an
        encoder step beyond it is refused as implausible. ``secoc_key`` (16 bytes; None: no
        SecOC) and ``nvm`` (the EPOCH cell; None with a key: secured commands unavailable)."""
        self._hal = hal
        self.errors = ErrorMask()
        self.state = State.INIT
        self.reason = Reason.NONE
        if validate(params) is not ConfigReason.OK:
            self.errors.set(ErrorFlag.CONFIG_INVALID)
            self.state = State.FAULT
            self.reason = Reason.CONFIG_INVALID
        self.params = params
        self.odometry = Odometry(derive_constants(params, self.errors), self.errors)
        self.max_wheel_speed_mm_s = max_wheel_speed_mm_s
        self._max_counts_per_period = self._step_bounds()
        self.mailbox = Mailbox()
        # The window widens once per tick (not per frame): a replay cannot widen it.
        self.rx_encoders = E2EReceiver(
            fr.WHEEL_ENCODERS_DATA_IDS, max_delta_counter_init=0, window_per_period=True
        )
        self.rx_set_pose = E2EReceiver(fr.ODOM_SET_POSE_DATA_IDS, max_delta_counter_init=15)
        self.rx_config = E2EReceiver(fr.ODOM_CONFIG_DATA_IDS, max_delta_counter_init=15)
        self.rx_nav_goal = E2EReceiver(fr.NAV_GOAL_DATA_IDS, max_delta_counter_init=15)
        self.nav = Navigator(self.errors)
        self._motor_cmd_due = False
        self.ticks = 0  # u32 uptime in ticks
        self.frames_filtered = 0  # u32: IDs this node does not listen to
        self.frames_bad_length = 0  # u32: not 8 bytes (rejected before the E2E check)
        self.tx_dropped = 0  # u32: the driver refused a frame
        self._tx_counters: dict[int, int] = {}
        self._enc_counter = 0  # COUNTER of the last accepted WHEEL_ENCODERS frame
        self._enc_prev_counter: int | None = None
        self._wire_prev: tuple[int, int] | None = None
        self._counts_u32 = (0, 0)
        self._counts_prev: tuple[int, int] | None = None  # counters of the last accepted frame
        self.time_periods = 0  # u32: 10 ms periods since reset, by the timer (ticks run or not)
        self._timer_prev_us: int | None = None  # u32 timer value at the previous tick
        self._timer_rest_us = 0  # i32, within +-TICK_PERIOD_US/2: time not yet counted
        self.periods_lost = 0  # u32: periods the firmware did not run (stalls)
        self.frames_implausible = 0  # u32: WHEEL_ENCODERS refused by the plausibility bound
        self._overflows_seen = 0
        # Refused frames consistent among themselves: (left, right, COUNTER) of the first, last.
        self._resync_first: tuple[int, int, int] | None = None
        self._resync_last: tuple[int, int, int] = (0, 0, 0)
        self._resync_frames = 0
        self._ticks_since_encoder = 0  # periods (of firmware time) since the last accepted frame
        self._reason_tick = 0  # u32: the tick that set ``reason``
        # Periods since the last accepted frame's sample is known to have been taken (frames
        # taken in a tick that lost time were sampled at unknown times during the stall).
        self._periods_since_sample = 0  # u16, saturated
        self._time_lost_now = False  # this tick came WATCHDOG_TICKS periods or more late
        self._samples_stale = False  # the last accepted frame was taken in a tick that lost time
        self._tick_budget = 0  # _periods_since_sample at the start of this tick
        # The steps since the last twist update (one tick; two after a tick that lost time).
        self._tick_ds_q20_m = 0  # i64, saturated to +-2^32 (4096 m)
        self._tick_dheading_q30_rad = 0  # i64, saturated to +-2^32 (4 rad)
        self._tick_steps = 0
        self._tick_periods = 0  # u16, saturated: the sample periods the summed steps span
        self._tick_carried = False  # the sums hold steps of a tick that lost time
        self._this_step_periods = 1  # u32: the sample periods of the step being accepted
        self._tick_late = 0  # u32: periods this tick came after its due time
        self._good_in_a_row = 0
        self._twist_mm_s = 0
        self._twist_mrad_s = 0
        self._page_index = 0
        self._staged_pose: dict[int, int] = {}
        self._staged_config: dict[int, int] = {}
        self.secoc: SecuredCommands | None = None
        self.rx_auth = E2EReceiver(fr.ODOM_AUTH_DATA_IDS, max_delta_counter_init=15)
        if secoc_key is not None:  # boot: EPOCH + 1 written to the NVM before anything else
            self.secoc = SecuredCommands(SecocReceiver(secoc_key, nvm or _NoNvm()))

    # --- ISR context -------------------------------------------------------------------------

    def isr_can_rx(self, can_id: int, data: bytes) -> None:
        """CAN receive interrupt: copy the frame into the mailbox (or count the overflow)."""
        if not self.mailbox.put(can_id, data):
            self.errors.set(ErrorFlag.MAILBOX_OVERFLOW)

    def isr_rx_overrun(self) -> None:
        """CAN controller overrun interrupt: its receive FIFO dropped frames (counted as one
        mailbox overflow: the hardware flags the event, not the number)."""
        self.mailbox.overflows = wrap_u32(self.mailbox.overflows + 1)
        self.errors.set(ErrorFlag.MAILBOX_OVERFLOW)

    def isr_bus_state(self, bus_off: bool) -> None:
        """CAN controller status interrupt: bus-off entered (True) or recovered (False)."""
        if bus_off:
            self.errors.set(ErrorFlag.BUS_OFF)

    # --- the periodic tick -------------------------------------------------------------------

    def tick(self, now_us: int | None = None) -> None:
        """One period of the main loop, in the fixed order of the module docstring.

        ``now_us``: the board's free-running u32 microsecond timer when the tick was released
        (None: no timer, one period has passed)."""
        self._check_overflows()
        periods = self._advance_time(now_us)  # after: a stall's overrun is TIME_LOST
        self._tick_late = periods - 1 if periods > 0 else 0  # its frames may have queued so long
        # The E2E window widens with time; fully after frames of unknown age (a stall's backlog).
        widen = COUNTER_MASK if self._samples_stale else min(periods, COUNTER_MASK)
        for _ in range(widen):
            self.rx_encoders.new_period()
        self._tick_budget = self._periods_since_sample
        self._drain_mailbox()
        self._expire_held()
        if self._tick_steps and not self._time_lost_now:
            carried = self._tick_carried  # a stall's backlog: its frames' periods are unknown
            self._update_twist(max(self._tick_budget, 1) if carried else self._tick_periods)
        elif self._tick_steps:
            self._tick_carried = True
        self._navigate()
        self._transmit_scheduled()
        self._watchdog()
        self.ticks = wrap_u32(self.ticks + 1)

    def _drain_mailbox(self) -> None:
        """Steps 1-3: every frame in arrival order, to its handler."""
        encoder_seen = False
        frame = self.mailbox.get()
        while frame is not None:
            can_id, data = frame
            if can_id == fr.WHEEL_ENCODERS_ID:
                encoder_seen = True
                self._on_wheel_encoders(data)
            elif can_id == fr.ODOM_SET_POSE_ID:
                self._on_set_pose(data)
            elif can_id == fr.ODOM_CONFIG_ID:
                self._on_config(data)
            elif can_id == fr.NAV_GOAL_ID:
                self._on_nav_goal(data)
            elif can_id == fr.ODOM_AUTH_ID and self.secoc is not None:
                self._on_auth(data)
            else:
                self.frames_filtered = wrap_u32(self.frames_filtered + 1)
            frame = self.mailbox.get()
        if not encoder_seen:
            self.rx_encoders.check(None)

    def _advance_time(self, now_us: int | None) -> int:
        """Firmware time: the periods elapsed on the timer since the previous tick, returned;
        rounded, the remainder carried to the next tick so jitter never drifts the clock
        (u32 elapsed: the timer may wrap, every 71.6 min)."""
        periods = 1
        if now_us is not None:
            if self._timer_prev_us is not None:
                elapsed_us = wrap_u32(now_us - self._timer_prev_us) + self._timer_rest_us
                periods = (elapsed_us + TICK_PERIOD_US // 2) // TICK_PERIOD_US
                self._timer_rest_us = elapsed_us - periods * TICK_PERIOD_US
            self._timer_prev_us = now_us & U32_MAX
        self.time_periods = wrap_u32(self.time_periods + periods)
        self._ticks_since_encoder = min(self._ticks_since_encoder + periods, STEP_PERIODS_MAX)
        self._periods_since_sample = min(self._periods_since_sample + periods, STEP_PERIODS_MAX)
        self._time_lost_now = periods >= LOST_TIME_PERIODS
        if self._time_lost_now:
            self.periods_lost = wrap_u32(self.periods_lost + periods - 1)
            self.errors.set(ErrorFlag.TIME_LOST)
            self._degrade(Reason.TIME_LOST)
        return periods

    def _check_overflows(self) -> None:
        """Frames the receive ISR dropped since the previous tick: DEGRADED (MAILBOX_OVERFLOW)."""
        overflows = self.mailbox.overflows
        if overflows != self._overflows_seen:
            self._overflows_seen = overflows
            self._degrade(Reason.MAILBOX_OVERFLOW)

    def _degrade(self, reason: Reason) -> None:
        """OK or DEGRADED -> DEGRADED for ``reason`` (INIT and FAULT stay); recovery restarts.
        COUNTER_RESET is never replaced by a later cause (those still set their error bits):
        only ODOM_SET_POSE APPLY clears it, or a later cause would let the firmware report OK
        on a pose that lost its continuity."""
        if self.state is State.OK or self.state is State.DEGRADED:
            self.state = State.DEGRADED
            if self.reason is not Reason.COUNTER_RESET:
                self.reason = reason
            self._good_in_a_row = 0
            self._reason_tick = self.ticks

    # --- step 2-3: received frames -----------------------------------------------------------

    def _e2e(self, receiver: E2EReceiver, data: bytes) -> bool:
        """The Profile 2 check; True when the frame may be used (OK or OKSOMELOST)."""
        if len(data) != 8:
            self.frames_bad_length = wrap_u32(self.frames_bad_length + 1)
            self.errors.set(ErrorFlag.E2E_ERROR)
            return False
        status = receiver.check(data)
        if status is E2EStatus.OK or status is E2EStatus.OKSOMELOST:
            return True
        if status is not E2EStatus.REPEATED:
            self.errors.set(ErrorFlag.E2E_ERROR)
        return False

    def _on_wheel_encoders(self, data: bytes) -> None:
        if not self._e2e(self.rx_encoders, data):
            return
        frame = fr.unpack_wheel_encoders(data)
        wire = (frame.left_count, frame.right_count)
        counts = self._extend_counters(wire)
        periods = self._step_periods(frame.counter)
        if not self._plausible(self._counts_prev, counts, periods):
            self._on_implausible(frame.counter, wire, counts)
            return
        self._resync_first = None
        self._this_step_periods = periods
        self._accept_encoders(frame.counter, wire, counts)

    def _accept_encoders(
        self, counter: int, wire: tuple[int, int], counts: tuple[int, int]
    ) -> None:
        """Integrate an accepted WHEEL_ENCODERS frame; it feeds the watchdog's recovery."""
        self._commit_counters(wire, counts)
        if self.state is not State.FAULT and self.odometry.step_counts(counts[0], counts[1]):
            self._sum_step()
        self._enc_prev_counter = counter
        self._enc_counter = counter
        self._ticks_since_encoder = 0
        self._samples_stale = self._time_lost_now
        if not self._time_lost_now:
            self._periods_since_sample = 0
        if self._good_in_a_row < RECOVERY_FRAMES:
            self._good_in_a_row += 1
        if self.state is State.INIT:
            self.state = State.OK

    def _extend_counters(self, wire: tuple[int, int]) -> tuple[int, int]:
        """The hardware counters from their low 24 bits on the wire (nothing is stored).

        A 16-bit counter fits the wire as it is. A 32-bit one is rebuilt by adding the wire's
        wrap-safe 24-bit delta (C: ``prev += (int32_t)((wire - prev_wire) << 8) >> 8``).
        """
        if self.odometry.consts.counter_bits <= WIRE_COUNTER_BITS or self._wire_prev is None:
            return wire
        d_left = wrap_signed(wire[0] - self._wire_prev[0], WIRE_COUNTER_BITS)
        d_right = wrap_signed(wire[1] - self._wire_prev[1], WIRE_COUNTER_BITS)
        return (self._counts_u32[0] + d_left) & U32_MAX, (self._counts_u32[1] + d_right) & U32_MAX

    def _commit_counters(self, wire: tuple[int, int], counts: tuple[int, int]) -> None:
        """Take an accepted frame's counters as the base of the next deltas."""
        self._wire_prev = wire
        self._counts_u32 = counts
        self._counts_prev = counts

    def _step_periods(self, counter: int) -> int:
        """The encoder periods between this frame's sample and the last accepted one's: the
        COUNTER advance n (mod 16), plus the whole counter cycles that bring it nearest to the
        periods since that frame was accepted (0 for a second frame in one tick; after a tick that
        lost time, since the last sample before it), less the periods this tick came late (its
        frames waited in the mailbox meanwhile). Exact while the two frames' queueing, beyond
        that, differs by less than 8 periods (a frame held 15 ms lands two ticks late: the
        nearest cycle, not the one below); n in a regular stream (1)."""
        prev = self._enc_prev_counter
        if prev is None:
            return 1
        advance = ((counter - prev) & COUNTER_MASK) or COUNTER_VALUES
        since, late = self._periods_since_sample, self._tick_late
        budget = (since - late if since > late else 0) + COUNTER_VALUES // 2  # <= U16_MAX + 8
        if budget <= advance:
            return advance
        return advance + (((budget - advance) >> 4) << 4)

    def _step_bounds(self) -> tuple[int, int]:
        """Per wheel, the most counts one encoder period can hold at ``max_wheel_speed_mm_s``:
        ceil(v_max * T / travel per count) + 1 (a count edge may fall either side of a sample).
        Configuration time: a 128-bit muldiv, then u64 division."""
        c = self.odometry.consts
        travel_q48_m = muldiv_round_u64(
            self.max_wheel_speed_mm_s * ENCODER_PERIOD_US, 1 << 48, 1_000_000_000, self.errors
        )
        return (
            (travel_q48_m + c.m_per_count_left_q48_m - 1) // c.m_per_count_left_q48_m + 1,
            (travel_q48_m + c.m_per_count_right_q48_m - 1) // c.m_per_count_right_q48_m + 1,
        )

    def _plausible(
        self, prev: tuple[int, int] | None, counts: tuple[int, int], periods: int
    ) -> bool:
        """True when each wheel moved at most ``periods`` times its per-period bound (u64: at
        most 2^16 * 2^32) since ``prev`` (None: nothing to compare, plausible)."""
        if prev is None:
            return True
        bits = self.odometry.consts.counter_bits
        left_max, right_max = self._max_counts_per_period
        d_left = wrap_signed(counts[0] - prev[0], bits)
        d_right = wrap_signed(counts[1] - prev[1], bits)
        return abs(d_left) <= periods * left_max and abs(d_right) <= periods * right_max

    def _on_implausible(self, counter: int, wire: tuple[int, int], counts: tuple[int, int]) -> None:
        """Refuse the step (DEGRADED, IMPLAUSIBLE_STEP); ``RESYNC_FRAMES`` refused frames in a row
        that are plausible among themselves are a counter restart (COUNTER_RESET): re-prime on
        the first of them and integrate from there, never the jump."""
        self.frames_implausible = wrap_u32(self.frames_implausible + 1)
        self.errors.set(ErrorFlag.IMPLAUSIBLE_STEP)
        self._degrade(Reason.IMPLAUSIBLE_STEP)
        last = self._resync_last
        if self._resync_first is not None and self._plausible(
            (last[0], last[1]), counts, ((counter - last[2]) & COUNTER_MASK) or 1
        ):
            self._resync_frames += 1
        else:
            self._resync_first = (counts[0], counts[1], counter)
            self._resync_frames = 1
        self._resync_last = (counts[0], counts[1], counter)
        if self._resync_frames >= RESYNC_FRAMES:
            self._restart_counters(counter, wire, counts)

    def _restart_counters(
        self, counter: int, wire: tuple[int, int], counts: tuple[int, int]
    ) -> None:
        """The encoder counters restarted: prime on the first consistent frame, integrate from it
        up to ``counts`` (its periods from the COUNTER advance)."""
        first = self._resync_first
        if first is None:
            return
        self.errors.set(ErrorFlag.COUNTER_RESET)
        self._degrade(Reason.COUNTER_RESET)
        self._resync_first = None
        self._resync_frames = 0
        self.odometry.unprime()
        self.odometry.step_counts(first[0], first[1])
        self._enc_prev_counter = None
        self._this_step_periods = ((counter - first[2]) & COUNTER_MASK) or COUNTER_VALUES
        self._accept_encoders(counter, wire, counts)

    def _sum_step(self) -> None:
        """Add the step just integrated to this tick's sums (Q20 m, Q30 rad; i64, saturated)."""
        odo = self.odometry
        dheading_q30_rad = mul_shr_round_i64(odo.last_dheading_bam64, TWO_PI_Q60, 94, self.errors)
        self._tick_ds_q20_m = sat_range(
            self._tick_ds_q20_m + (odo.last_ds_q49_m >> 29),
            -TWIST_SUM_MAX,
            TWIST_SUM_MAX,
            self.errors,
        )
        self._tick_dheading_q30_rad = sat_range(
            self._tick_dheading_q30_rad + dheading_q30_rad,
            -TWIST_SUM_MAX,
            TWIST_SUM_MAX,
            self.errors,
        )
        self._tick_steps += 1
        self._tick_periods = min(self._tick_periods + self._this_step_periods, STEP_PERIODS_MAX)

    def _update_twist(self, periods: int) -> None:
        """Speeds over this tick's steps, which cover ``periods`` (1 .. STEP_PERIODS_MAX): the
        sample periods of the steps (``_step_periods``: the COUNTER advance, whole counter
        cycles from firmware time), so lost frames and a late frame (accepted a tick after its
        period: one step in a tick of two periods, then two steps in a tick of one) give the true
        mean speed; after a stall (summed over two ticks) the firmware time since the last sample
        before it, as the backlog's sample times are unknown. Products < 2^32 * 10^9 < 2^63. The
        sums restart."""
        dt_us = periods * ENCODER_PERIOD_US
        self._twist_mm_s = div_round_i64(self._tick_ds_q20_m * 1_000_000_000, dt_us << 20)
        self._twist_mrad_s = div_round_i64(self._tick_dheading_q30_rad * 1_000_000_000, dt_us << 30)
        self._tick_ds_q20_m = 0
        self._tick_dheading_q30_rad = 0
        self._tick_steps = 0
        self._tick_periods = 0
        self._tick_carried = False

    # --- SecOC: verify before acting ---

    def _secured(self, request: AuthRequest, data: bytes) -> bool:
        """True when the frame (E2E OK) was held for its ODOM_AUTH instead of acted on now; a
        frame it displaced is refused (NACK AUTH_MISSING)."""
        if self.secoc is None:
            return False
        displaced = self.secoc.hold(request, data, self.ticks)
        if displaced is not None:
            self._nack_held(displaced, AuthStatus.MISSING)
        return True

    def _on_auth(self, data: bytes) -> None:
        """ODOM_AUTH: verify the held frame it names; act on it, or NACK it with the verdict."""
        if self.secoc is None or not self._e2e(self.rx_auth, data):
            return
        result = self.secoc.authenticate(fr.unpack_odom_auth(data))
        if result is None:  # nothing held for it: counted (orphans), no answer
            return
        status, held = result
        if status is not AuthStatus.OK:
            self._nack_held(held, status)
        elif held.can_id == fr.ODOM_SET_POSE_ID:
            self._act_set_pose(held.pdu)
        elif held.can_id == fr.ODOM_CONFIG_ID:
            self._act_config(held.pdu)
        else:
            self._act_nav_goal(held.pdu)

    def _expire_held(self) -> None:
        """Held frames whose ODOM_AUTH did not come in time: NACK AUTH_MISSING."""
        if self.secoc is None:
            return
        held = self.secoc.expire(self.ticks)
        while held is not None:
            self._nack_held(held, AuthStatus.MISSING)
            held = self.secoc.expire(self.ticks)

    def _nack_held(self, held: Held, status: AuthStatus) -> None:
        """ODOM_ACK NACK for a held secured frame, REASON the AUTH verdict (7..10)."""
        frame: fr.OdomSetPose | fr.OdomConfig | fr.NavGoal
        if held.can_id == fr.ODOM_SET_POSE_ID:
            frame = fr.unpack_odom_set_pose(held.pdu)
        elif held.can_id == fr.ODOM_CONFIG_ID:
            frame = fr.unpack_odom_config(held.pdu)
        else:
            frame = fr.unpack_nav_goal(held.pdu)
        self._ack(held.can_id, frame, fr.AckResult.NACK, fr.AckReason(int(status)))

    def _send_freshness(self) -> None:
        """ODOM_FRESHNESS when due (boot, refusal, rollover, unavailable) and every second."""
        if self.secoc is None:
            return
        receiver = self.secoc.receiver
        cause = receiver.sync_cause
        if cause is None and self.ticks % FRESHNESS_PERIOD_TICKS == 0:
            cause = FreshnessCause.PERIODIC
        if cause is not None:
            receiver.sync_cause = None
            counter = self._next_counter(fr.ODOM_FRESHNESS_ID)
            self._send(fr.ODOM_FRESHNESS_ID, receiver.freshness_frame(counter, cause))

    # --- the command handlers ---

    def _on_set_pose(self, data: bytes) -> None:
        if self._e2e(self.rx_set_pose, data) and not self._secured(AuthRequest.ODOM_SET_POSE, data):
            self._act_set_pose(data)

    def _act_set_pose(self, data: bytes) -> None:
        frame = fr.unpack_odom_set_pose(data)
        field = frame.field
        if field == fr.SetPoseField.APPLY:
            x_q40, y_q40, heading = self._pose_with(self._staged_pose)
            self.odometry.set_pose(x_q40, y_q40, heading)
            self._staged_pose.clear()
            if self.reason is Reason.COUNTER_RESET:  # a pose given again: recovery may proceed
                self.reason = Reason.NONE
        elif field in (fr.SetPoseField.X, fr.SetPoseField.Y, fr.SetPoseField.HEADING):
            self._staged_pose[field] = frame.value
        else:
            self._ack(fr.ODOM_SET_POSE_ID, frame, fr.AckResult.NACK, fr.AckReason.UNKNOWN_FIELD)
            return
        self._ack(fr.ODOM_SET_POSE_ID, frame, fr.AckResult.ACK, fr.AckReason.OK)

    def _pose_with(self, staged: dict[int, int]) -> tuple[int, int, int]:
        """The current pose overwritten by the staged fields (X/Y in 0.1 mm, heading in BAM16)."""
        odo = self.odometry
        x_q40 = odo.x_q40_m
        y_q40 = odo.y_q40_m
        heading = odo.heading_bam64
        if fr.SetPoseField.X in staged:
            x_q40 = _q40_from_100um(staged[fr.SetPoseField.X])
        if fr.SetPoseField.Y in staged:
            y_q40 = _q40_from_100um(staged[fr.SetPoseField.Y])
        if fr.SetPoseField.HEADING in staged:
            heading = (staged[fr.SetPoseField.HEADING] << 48) & U64_MAX
        return x_q40, y_q40, heading

    def _on_config(self, data: bytes) -> None:
        if self._e2e(self.rx_config, data) and not self._secured(AuthRequest.ODOM_CONFIG, data):
            self._act_config(data)

    def _act_config(self, data: bytes) -> None:
        frame = fr.unpack_odom_config(data)
        if frame.param == fr.ConfigParam.APPLY:
            self._apply_config(frame)
        elif frame.param in _CONFIG_FIELDS:
            self._staged_config[frame.param] = frame.value
            self._ack(fr.ODOM_CONFIG_ID, frame, fr.AckResult.ACK, fr.AckReason.OK)
        else:
            self._ack(fr.ODOM_CONFIG_ID, frame, fr.AckResult.NACK, fr.AckReason.UNKNOWN_FIELD)

    def _apply_config(self, frame: fr.OdomConfig) -> None:
        """Validate the current parameters overwritten by the staged ones; commit all or nothing."""
        values = {name: getattr(self.params, name) for name in _CONFIG_FIELDS.values()}
        for param, value in self._staged_config.items():
            values[_CONFIG_FIELDS[fr.ConfigParam(param)]] = value
        self._staged_config.clear()
        candidate = RobotParams(**values)
        reason = validate(candidate)
        if reason is not ConfigReason.OK:
            self.errors.set(ErrorFlag.CONFIG_INVALID)
            ack_reason = (
                fr.AckReason.INCONSISTENT
                if reason is ConfigReason.GEOMETRY_ABSURD
                else fr.AckReason.OUT_OF_RANGE
            )
            self._ack(fr.ODOM_CONFIG_ID, frame, fr.AckResult.NACK, ack_reason)
            return
        if candidate.counter_bits != self.params.counter_bits:
            self.odometry.unprime()
            self._wire_prev = None
            self._counts_prev = None
        self.params = candidate
        self.odometry.reconfigure(derive_constants(candidate, self.errors))
        self._max_counts_per_period = self._step_bounds()
        if self.state is State.FAULT:
            self.state = State.INIT
            self.reason = Reason.NONE
        self._ack(fr.ODOM_CONFIG_ID, frame, fr.AckResult.ACK, fr.AckReason.OK)

    def _on_nav_goal(self, data: bytes) -> None:
        if self._e2e(self.rx_nav_goal, data) and not self._secured(AuthRequest.NAV_GOAL, data):
            self._act_nav_goal(data)

    def _act_nav_goal(self, data: bytes) -> None:
        frame = fr.unpack_nav_goal(data)
        reason = self.nav.request(frame, self.state is State.OK)
        result = fr.AckResult.ACK if reason is fr.AckReason.OK else fr.AckResult.NACK
        self._ack(fr.NAV_GOAL_ID, frame, result, reason)

    def _ack(
        self,
        request_id: int,
        frame: fr.OdomSetPose | fr.OdomConfig | fr.NavGoal,
        result: fr.AckResult,
        reason: fr.AckReason,
    ) -> None:
        data = fr.pack_odom_ack(
            self._next_counter(fr.ODOM_ACK_ID),
            frame.counter,
            request_id,
            frame.param if isinstance(frame, fr.OdomConfig) else frame.field,
            result,
            reason,
            self.errors,
        )
        self._send(fr.ODOM_ACK_ID, data)

    # --- step 4: controllers -----------------------------------------------------------------

    def _navigate(self) -> None:
        """Navigation every NAV_PERIOD_TICKS, from the on-board pose; it decides MOTOR_CMD."""
        self._motor_cmd_due = False
        if self.ticks % NAV_PERIOD_TICKS == 0:
            odo = self.odometry
            self._motor_cmd_due = self.nav.step(
                odo.x_q40_m,
                odo.y_q40_m,
                odo.heading_bam64,
                self.params.wheelbase_nm,
                self.state is State.OK,
            )

    # --- step 5: scheduled transmissions -----------------------------------------------------

    def _transmit_scheduled(self) -> None:
        if self._motor_cmd_due:
            nav = self.nav
            cmd = fr.pack_motor_cmd(
                self._next_counter(fr.MOTOR_CMD_ID), nav.left_mm_s, nav.right_mm_s, self.errors
            )
            self._send(fr.MOTOR_CMD_ID, cmd)
        if self.ticks % POSE_PERIOD_TICKS == 0 and self.state is not State.INIT:
            self._send_pose_and_twist()
        if self.ticks % STATUS_PERIOD_TICKS == 0:
            self._send_status()
        if self.nav.changed or self.ticks % STATUS_PERIOD_TICKS == 0:
            self._send_nav_status()
        self._send_freshness()

    def _send_nav_status(self) -> None:
        """NAV_STATUS; DISTANCE is clamped to its 65.535 m range here (a display limit)."""
        nav = self.nav
        nav.changed = False
        distance_mm = min(div_round_i64(nav.distance_um, 1000), U16_MAX)
        heading_error_bam16 = wrap_i16((nav.heading_error_bam32 + (1 << 15)) >> 16)
        data = fr.pack_nav_status(
            self._next_counter(fr.NAV_STATUS_ID),
            nav.state,
            nav.goal_id,
            nav.depth,
            distance_mm,
            heading_error_bam16,
            self.errors,
        )
        self._send(fr.NAV_STATUS_ID, data)

    def _send_pose_and_twist(self) -> None:
        odo = self.odometry
        enc = self._enc_counter
        x_100um = mul_shr_round_i64(odo.x_q40_m, 10_000, 40, self.errors)
        y_100um = mul_shr_round_i64(odo.y_q40_m, 10_000, 40, self.errors)
        heading_rounded = odo.heading_bam64 + (1 << 47)  # u64 add: its carry is a whole turn
        heading_bam16 = (heading_rounded >> 48) & 0xFFFF
        turns = wrap_i32(odo.heading_turns + (heading_rounded >> 64))  # TURNS of the rounded value
        distance_mm = (odo.distance_q40_m * 1000 + (1 << 39)) >> 40
        e = self.errors
        counter = self._next_counter
        self._send(
            fr.ODOM_POSE_X_ID,
            fr.pack_odom_pose_x(counter(fr.ODOM_POSE_X_ID), enc, x_100um, heading_bam16, e),
        )
        self._send(
            fr.ODOM_POSE_Y_ID,
            fr.pack_odom_pose_y(counter(fr.ODOM_POSE_Y_ID), enc, y_100um, turns, e),
        )
        twist = fr.pack_odom_twist(
            counter(fr.ODOM_TWIST_ID), enc, self._twist_mm_s, self._twist_mrad_s, distance_mm, e
        )
        self._send(fr.ODOM_TWIST_ID, twist)

    def _send_status(self) -> None:
        summary = fr.pack_odom_status_summary(
            self._next_counter(fr.ODOM_STATUS_ID),
            self.state,
            self.odometry.consts.integrator,
            self.errors.bits,
            self.time_periods // TICKS_PER_SECOND,
            self.errors,
            self.reason,
        )
        self._send(fr.ODOM_STATUS_ID, summary)
        page = _ROTATING_PAGES[self._page_index]
        self._page_index = (self._page_index + 1) % len(_ROTATING_PAGES)
        self._send(fr.ODOM_STATUS_ID, self._status_page(page))

    def _status_page(self, page: fr.StatusPage) -> bytes:
        counter = self._next_counter(fr.ODOM_STATUS_ID)
        if page is fr.StatusPage.FRAME_TOTALS:
            return fr.pack_odom_status_frame_totals(
                counter, self.rx_encoders.lost_frames, self.frames_rejected, self.mailbox.overflows
            )
        rx = {
            fr.StatusPage.E2E_WHEEL_ENCODERS: self.rx_encoders,
            fr.StatusPage.E2E_ODOM_SET_POSE: self.rx_set_pose,
            fr.StatusPage.E2E_ODOM_CONFIG: self.rx_config,
            fr.StatusPage.E2E_NAV_GOAL: self.rx_nav_goal,
        }[page]
        return fr.pack_odom_status_e2e(
            counter,
            page,
            rx.accepted(),
            rx.lost_frames,
            rx.count_repeated,
            rx.count_error,
            rx.count_wrongsequence,
        )

    @property
    def frames_rejected(self) -> int:
        """Frames refused by the E2E check, for their length or as implausible (u32, wrapping)."""
        total = self.frames_bad_length + self.frames_implausible
        for rx in (self.rx_encoders, self.rx_set_pose, self.rx_config, self.rx_nav_goal):
            total += rx.count_error + rx.count_wrongsequence + rx.count_repeated
        return wrap_u32(total)

    def _next_counter(self, can_id: int) -> int:
        counter = self._tx_counters.get(can_id, -1)
        counter = (counter + 1) & COUNTER_MASK
        self._tx_counters[can_id] = counter
        return counter

    def _send(self, can_id: int, data: bytes) -> None:
        if not self._hal.transmit(can_id, data):
            self.tx_dropped = wrap_u32(self.tx_dropped + 1)

    # --- step 6: the watchdog ----------------------------------------------------------------

    def _watchdog(self) -> None:
        """Encoders silent for WATCHDOG_TICKS periods of firmware time -> DEGRADED; back to OK
        after RECOVERY_FRAMES accepted frames with no new cause."""
        if self.state is State.INIT or self.state is State.FAULT:
            return
        if self._ticks_since_encoder >= WATCHDOG_TICKS:
            self.errors.set(ErrorFlag.ENCODER_TIMEOUT)
            if self.state is State.OK or (  # a cause raised in this very tick is kept
                self.reason is not Reason.ENCODER_TIMEOUT and self._reason_tick != self.ticks
            ):
                self._degrade(Reason.ENCODER_TIMEOUT)
            self._good_in_a_row = 0
        elif (
            self.state is State.DEGRADED
            and self._good_in_a_row >= RECOVERY_FRAMES
            and self.reason is not Reason.COUNTER_RESET  # the pose lost its continuity
        ):
            self.state = State.OK
            self.reason = Reason.NONE


class _NoNvm:
    """No NVM cell given: every write fails, so secured commands are unavailable (fail closed)."""

    def read_epoch(self) -> int:
        return 0

    def write_epoch(self, epoch: int) -> bool:
        return False


def _q40_from_100um(value_100um: int) -> int:
    """0.1 mm units (i32) to Q40 metres (i64), exactly rounded without a 72-bit intermediate:
    whole metres shifted, plus the remainder (< 10^4, so ``r << 40`` < 2^54) divided."""
    metres, remainder_100um = divmod(value_100um, 10_000)  # floor semantics, remainder >= 0
    return (metres << 40) + div_round_i64(remainder_100um << 40, 10_000)
