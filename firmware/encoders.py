"""Step 3 for WHEEL_ENCODERS: from the wire's 24-bit counts to an integrated, plausible step.

Every frame that passes its E2E check is extended to the hardware counters' width (16 or 32 bits,
ODrive style), then checked against the robot's maximum rim speed
(``RobotParams.max_wheel_speed_mm_s``) over the most encoder periods that can separate it from the
last accepted sample. A plausible step is integrated (``firmware.odometry``) and summed into the
twist; an implausible one is refused (DEGRADED, IMPLAUSIBLE_STEP). ``RESYNC_FRAMES`` refused frames
consistent with each other but not with the last accepted one are a counter restart (COUNTER_RESET):
the odometry is re-primed on the first of them and the jump itself is never integrated. The counters
are absolute, so the first frame after a gap carries the distance driven meanwhile.

A forged payload that passes E2E (1 in 256 pass Profile 2's CRC under a flood on the encoder ID)
meets the same bound, also after the mailbox dropped frames (``_dropped_bound_periods``), and on a
robot with 16-bit counters it is refused first when it sets the wire's top 8 bits, which no
genuine frame does (``_refuse_unused_bits``): neither its step nor a restart is taken from it.

A restarted motor controller is told by its age (CTRL_UPTIME: ``firmware.restartage``) and taken
when the next frame confirms it (``firmware.restarthold``); a step too long to read its counts
unambiguously is never integrated (``firmware.ambiguity``); a step refused against a frame that
may have waited out a silence is judged again from the sample before it (``firmware.sampledoubt``).
"""

from __future__ import annotations

from odocan.firmware import frames as fr
from odocan.firmware.ambiguity import least_ambiguous_periods
from odocan.firmware.clock import FirmwareClock
from odocan.firmware.config import MAX_WHEEL_SPEED_DEFAULT_MM_S, unused_wire_bits
from odocan.firmware.e2e import COUNTER_MASK, FRAME_LEN, E2EReceiver, p02_crc
from odocan.firmware.errors import ErrorFlag, ErrorMask, Reason, State
from odocan.firmware.fixmath import U16_MAX, U32_MAX, muldiv_round_u64, wrap_signed, wrap_u32
from odocan.firmware.health import RECOVERY_FRAMES, Health
from odocan.firmware.odometry import Odometry
from odocan.firmware.reception import Reception
from odocan.firmware.restartage import CTRL_UPTIME_MAX as CTRL_UPTIME_MAX
from odocan.firmware.restartage import PERIODS_PER_S as PERIODS_PER_S
from odocan.firmware.restartage import RESTART_SLACK_PERIODS as RESTART_SLACK_PERIODS
from odocan.firmware.restartage import aged_uptime, young_counts
from odocan.firmware.restarthold import RestartHold
from odocan.firmware.sampledoubt import accepted_doubt, doubted_periods, step_periods
from odocan.firmware.twist import ENCODER_PERIOD_US, Twist

# The plausibility bound of a robot whose parameters state none (RobotParams.max_wheel_speed_mm_s)
MAX_WHEEL_SPEED_MM_S = MAX_WHEEL_SPEED_DEFAULT_MM_S
RESYNC_FRAMES = 3  # frames consistent with each other, not with the last one: counters restarted
COUNTER_VALUES = 16  # E2E COUNTER values (4 bits): one whole counter cycle
STEP_PERIODS_MAX = U16_MAX  # the twist's dt and the plausibility bound saturate here (655 s)
WIRE_COUNTER_BITS = 24  # WHEEL_ENCODERS carries the low 24 bits of each counter

Counts = tuple[int, int]  # (left, right) counter values
_FAULT = State.FAULT  # the enumerators as module constants (a 3.11 enum attribute read: ~0.14 us)
_INIT = State.INIT


class EncoderInput:
    """The WHEEL_ENCODERS receiver: E2E state, the counters' base, plausibility and restarts."""

    # Fixed fields (C: the struct; 35 would outgrow CPython 3.11's shared-key instance dicts and
    # every read would be a dict lookup); ``__dict__`` kept for tests that plant a method.
    __slots__ = (
        "__dict__",
        "_clock",
        "_count_half",
        "_counter_bits",
        "_counts_prev",
        "_counts_u32",
        "_dropped_at_accept",
        "_dropped_before",
        "_dropped_seen",
        "_enc_prev_counter",
        "_errors",
        "_health",
        "_max_counts_per_period",
        "_odometry",
        "_overflows_at_accept",
        "_periods_since_sample",
        "_reception",
        "_resync_first",
        "_resync_frames",
        "_resync_last",
        "_sample_doubt",
        "_samples_stale",
        "_this_step_periods",
        "_tick_late",
        "_twist",
        "_uptime_now",
        "_uptime_prev",
        "_wide_counters",
        "_wire_prev",
        "_wire_unused_mask",
        "enc_counter",
        "frames_dropped",
        "frames_implausible",
        "max_wheel_speed_mm_s",
        "periods_since_frame",
        "rx",
        "tick_budget",
    )

    def __init__(
        self,
        odometry: Odometry,
        health: Health,
        clock: FirmwareClock,
        twist: Twist,
        reception: Reception,
        max_wheel_speed_mm_s: int,
    ) -> None:
        """``max_wheel_speed_mm_s``: the fastest rim speed either wheel can reach (u16 mm/s)."""
        self._odometry = odometry
        self._health = health
        self._errors: ErrorMask = health.errors
        self._clock = clock
        self._twist = twist
        self._reception = reception
        self.max_wheel_speed_mm_s = max_wheel_speed_mm_s
        self._counter_bits = odometry.consts.counter_bits  # u8: the counters' width (16 or 32)
        self._count_half = 1 << (self._counter_bits - 1)  # u32: half the counters' range
        self._wide_counters = self._counter_bits > WIRE_COUNTER_BITS  # wider than the wire's
        self._wire_unused_mask = unused_wire_bits(self._counter_bits)  # u32: never set
        self._max_counts_per_period = self.step_bounds()
        self._ambiguous_periods = self._least_ambiguous_periods()
        # The window widens once per tick (not per frame): a replay cannot widen it.
        self.rx = E2EReceiver(
            fr.WHEEL_ENCODERS_DATA_IDS, max_delta_counter_init=0, window_per_period=True
        )
        self.enc_counter = 0  # COUNTER of the last accepted WHEEL_ENCODERS frame
        self._enc_prev_counter: int | None = None
        self._wire_prev: Counts | None = None
        self._counts_u32 = (0, 0)
        self._counts_prev: Counts | None = None  # counters of the last accepted frame
        self._uptime_prev = 0  # u8: CTRL_UPTIME of the last accepted frame (0: not reported)
        self._uptime_now = 0  # u8: CTRL_UPTIME of the frame being handled
        self.frames_implausible = 0  # u32: WHEEL_ENCODERS refused by the plausibility bound
        # Refused frames consistent among themselves: (left, right, COUNTER) of the first, last.
        self._resync_first: tuple[int, int, int] | None = None
        self._resync_last: tuple[int, int, int] = (0, 0, 0)
        self._resync_frames = 0
        self._hold = RestartHold()  # a frame saying its controller restarted, until the next
        self.periods_since_frame = 0  # periods (of firmware time) since the last accepted frame
        # Periods since the last accepted frame's sample is known to have been taken (frames
        # taken in a tick that lost time were sampled at unknown times during the stall).
        self._periods_since_sample = 0  # u16, saturated
        self._samples_stale = False  # the last accepted frame was taken in a tick that lost time
        self._sample_doubt = 0  # u16: periods the last frame's sample may lie before its tick
        self.tick_budget = 0  # _periods_since_sample at the start of this tick
        self._tick_late = 0  # u32: periods this tick came after its due time
        self._this_step_periods = 1  # u32: the sample periods of the step being accepted
        self._overflows_at_accept = 0  # u32: overflows_before when the last frame was accepted
        # WHEEL_ENCODERS frames the mailbox dropped (u32, wrapping; the ISR writes it) and its
        # value at this tick's start, at the previous tick's start, and when the last frame was
        # accepted: the frames dropped between that frame and this tick's are the difference of
        # the last two (a full ring drops the newest, so drops seen at a tick's start came after
        # every frame that tick drains).
        self.frames_dropped = 0
        self._dropped_seen = 0
        self._dropped_before = 0
        self._dropped_at_accept = 0

    # --- once per tick, before the drain ---

    def isr_dropped(self, data: bytes) -> None:
        """ISR context: the mailbox was full and dropped a frame on the WHEEL_ENCODERS ID; it is
        counted when it could be an encoder frame: 8 bytes whose Profile 2 CRC holds for the
        data ID of its COUNTER (one CRC8 over 9 bytes, table-driven: 9 loads in the ISR).

        Why: ``_counter_advance`` takes the advance nearest to d + 1 frames, d the drops counted
        here. Counting every frame on the ID let a flood of random payloads (8 000 frames/s: ~45
        dropped per 10 ms tick) make d ~45 for an advance of 1, so a step of one period was
        spread over ~45 (LINEAR_VEL 0.01 m/s at 0.5). Random payloads pass the CRC 1 time in 256
        (~0.2 counted per tick), far below the 8 frames of miscount the nearest advance absorbs;
        a genuine frame always passes, so a babbler's burst that drops 16+ genuine encoder frames
        is still counted whole (tests/test_babble_fast_bus.py). The sequence check is not done
        here: it would need the receiver's state, which the drain owns."""
        if len(data) != FRAME_LEN:
            return
        if data[0] != p02_crc(data, self.rx.data_ids[data[1] & COUNTER_MASK]):
            return
        self.frames_dropped = wrap_u32(self.frames_dropped + 1)

    def start_tick(self, periods: int) -> None:
        """``periods`` of firmware time passed: age the last sample, widen the E2E window (fully
        after frames of unknown age, a stall's backlog, and after frames the mailbox dropped:
        their count, not the window, bounds the step) and fix this tick's period budget."""
        self._dropped_before = self._dropped_seen
        self._dropped_seen = self.frames_dropped
        since_frame = self.periods_since_frame + periods  # u32, then saturated to u16
        if since_frame > STEP_PERIODS_MAX:
            since_frame = STEP_PERIODS_MAX
        self.periods_since_frame = since_frame
        since_sample = self._periods_since_sample + periods
        if since_sample > STEP_PERIODS_MAX:
            since_sample = STEP_PERIODS_MAX
        self._periods_since_sample = since_sample
        self._tick_late = periods - 1 if periods > 0 else 0  # its frames may have queued so long
        stale = (  # or _mailbox_dropped(), in line: once a tick
            self._samples_stale or self._overflows_at_accept != self._health.overflows_before
        )
        widen = COUNTER_MASK if stale or periods > COUNTER_MASK else periods
        self.rx.new_periods(widen)  # C: one saturating add, as ``widen`` calls of new_period
        self.tick_budget = since_sample

    def no_frame(self) -> None:
        """No WHEEL_ENCODERS in this tick's drain: the E2E receiver counts the missing frame."""
        self.rx.check(None)

    # --- a received frame ---

    def on_frame(self, data: bytes) -> None:
        """One WHEEL_ENCODERS frame from the mailbox. The common case (16-bit counters, no
        restart, a plausible step) runs in line: ~60 000 frames a simulated minute."""
        if not self._reception.usable(self.rx, data):
            return
        counter, left, right, uptime = fr.unpack_wheel_encoders_fields(data)
        if (left | right) & self._wire_unused_mask:
            self._refuse_unused_bits()
            return
        wire = (left, right)
        counts = self._extend_counters(wire) if self._wide_counters else wire
        self._uptime_now = uptime
        if self._hold.held:
            counts = self._release_held(counter, wire, counts)
        # A saturated CTRL_UPTIME (the controller up 15 s or more: nearly every frame) is never
        # below ``_aged_uptime`` (at most CTRL_UPTIME_MAX): no restart, the test not run.
        if uptime != CTRL_UPTIME_MAX and self._controller_restarted(uptime, wire, counter):
            self._hold.hold(counter, wire, uptime)  # taken when the next frame confirms it
            return
        advance = self._counter_advance(counter)
        periods = self._step_periods(advance)
        # The periods the plausibility bound allows this step: ``periods``, or, when the mailbox
        # may have dropped frames between the last accepted frame and this one (drops seen at a
        # tick's start from the accepting tick on, before this frame's tick: a full ring drops
        # the newest, so they came after that tick's frames), ``_dropped_bound_periods``. A
        # queued burst (a babbler held the bus) that overflows the mailbox can drop 16 or more
        # encoder frames, which the 4-bit COUNTER cannot count (E2E takes the 17th for the next
        # one) and firmware time cannot see (they all waited); bounded by ``periods`` alone such
        # a step was refused and the next frames taken for a counter restart. The counters are
        # absolute, so the wider step is exact.
        dropped = self._overflows_at_accept != self._health.overflows_before  # _mailbox_dropped
        bound = self._dropped_bound_periods(periods) if dropped else periods
        if bound >= self._ambiguous_periods and self._counts_prev is not None:
            self._reprime(counter, wire, counts)  # any step is as plausible as another
            return
        if not self._plausible(self._counts_prev, counts, bound):
            periods = self._doubted_step(counter, wire, counts, advance)
            if periods == 0:  # refused, or re-primed on
                return
        self._resync_first = None
        self._this_step_periods = periods
        # ENC_E2E_LOST (the E2E receiver's ``lost_frames``) also counts the whole COUNTER
        # cycles of frames the mailbox dropped, which the E2E check (the COUNTER mod 16) cannot
        # see: ``advance`` less the plain COUNTER advance (0 but after such drops).
        prev = self._enc_prev_counter
        if prev is not None:
            plain = ((counter - prev) & COUNTER_MASK) or COUNTER_VALUES
            if advance != plain:
                self.rx.lost_frames = wrap_u32(self.rx.lost_frames + advance - plain)
        self._accept(counter, wire, counts)

    def _doubted_step(self, counter: int, wire: Counts, counts: Counts, advance: int) -> int:
        """A step the bound refused, judged again over ``sampledoubt.doubted_periods``: those
        periods if plausible, else 0 (refused; re-primed on where they reach the ambiguous)."""
        periods = doubted_periods(advance, self._periods_since_sample, self._sample_doubt,
                                  self._tick_late)
        if periods == 0 or not self._plausible(self._counts_prev, counts, periods):
            self._on_implausible(counter, wire, counts)
            return 0
        if periods >= self._ambiguous_periods:
            self._reprime(counter, wire, counts)
            return 0
        return periods

    def _accept(self, counter: int, wire: Counts, counts: Counts) -> None:
        """Integrate an accepted WHEEL_ENCODERS frame; it feeds the watchdog's recovery."""
        self._wire_prev = wire  # the counters are the base of the next deltas
        self._counts_u32 = counts
        self._counts_prev = counts
        self._uptime_prev = self._uptime_now
        health = self._health
        if health.state is not _FAULT and self._odometry.step_counts(counts[0], counts[1]):
            self._twist.sum_step(self._this_step_periods)
        self._enc_prev_counter = counter
        self.enc_counter = counter
        self.periods_since_frame = 0
        time_lost_now = self._clock.time_lost_now
        self._samples_stale = time_lost_now
        self._sample_doubt = accepted_doubt(self._periods_since_sample, self._sample_doubt,
                                            time_lost_now)
        if not time_lost_now:
            self._periods_since_sample = 0
        self._overflows_at_accept = health.overflows_before
        self._dropped_at_accept = self._dropped_before
        if health.good_in_a_row < RECOVERY_FRAMES or health.state is _INIT:  # else a no-op
            health.encoder_accepted()

    def _extend_counters(self, wire: Counts) -> Counts:
        """The hardware counters from their low 24 bits on the wire (nothing is stored).

        A 16-bit counter fits the wire as it is. A 32-bit one is rebuilt by adding the wire's
        wrap-safe 24-bit delta (C: ``prev += (int32_t)((wire - prev_wire) << 8) >> 8``).
        """
        if not self._wide_counters or self._wire_prev is None:
            return wire
        d_left = wrap_signed(wire[0] - self._wire_prev[0], WIRE_COUNTER_BITS)
        d_right = wrap_signed(wire[1] - self._wire_prev[1], WIRE_COUNTER_BITS)
        return (self._counts_u32[0] + d_left) & U32_MAX, (self._counts_u32[1] + d_right) & U32_MAX

    # --- plausibility ---

    def _counter_advance(self, counter: int) -> int:
        """The frames from the last accepted one to this one (0: none accepted yet): the COUNTER
        advance (mod 16, 1..16), or, when the mailbox dropped d frames on the WHEEL_ENCODERS ID
        between them, the advance with that COUNTER nearest to d + 1 (d - 7 .. d + 8 frames
        between): d counts only dropped frames whose CRC holds (``isr_dropped``), yet forged
        ones that pass it (1 in 256) too, which E2E would have refused (an advance of 17 for 1
        would make the twist 17 times too low),
        and frames may also have been lost on the wire or refused (REPEATED) after the drops.
        Exact while those miscount d by less than 8; the plain advance when d is 0."""
        prev = self._enc_prev_counter
        if prev is None:
            return 0
        dropped = (self._dropped_before - self._dropped_at_accept) & U32_MAX  # (uint32_t)
        if dropped > STEP_PERIODS_MAX:
            dropped = STEP_PERIODS_MAX
        beyond = (counter - prev - 1 - dropped) & COUNTER_MASK
        advance = dropped + 1 + beyond
        if beyond >= COUNTER_VALUES // 2 and advance > COUNTER_VALUES:
            return advance - COUNTER_VALUES  # d counted frames that were not the encoders'
        return advance

    def _dropped_bound_periods(self, periods: int) -> int:
        """The periods a step may span after the mailbox dropped frames (u32, saturated at
        ``STEP_PERIODS_MAX``): ``periods`` (the advance counts the dropped frames whose CRC
        holds, ``isr_dropped``, to within the nearest-advance rule's half cycle), plus a whole
        COUNTER cycle (frames lost on the wire beyond the drops: the rule may have taken 16
        off), plus the firmware's own periods since the last accepted frame's sample (frames
        no one counted: an overrun, a silence). Was STEP_PERIODS_MAX (655 s of motion): any
        forged frame passing Profile 2's CRC (1 in 256) passed it too and was integrated
        (``odocan run --faults babble=2000:0x100``: 2.29 m off at seed 0)."""
        bound = periods + COUNTER_VALUES + self._periods_since_sample  # < 2^18
        return bound if bound < STEP_PERIODS_MAX else STEP_PERIODS_MAX

    def _refuse_unused_bits(self) -> None:
        """Refuse a frame whose counts set wire bits above the counters' width (a 16-bit
        counter's top 8 of the wire's 24): no controller sends it, a forged payload that passed
        Profile 2's CRC does (255 in 256 of them on a 16-bit robot). DEGRADED, IMPLAUSIBLE_STEP,
        as a step beyond the bound, but no part of a restart (the resync state is untouched).
        A held restart frame the next frame does not confirm is refused so too."""
        self.frames_implausible = wrap_u32(self.frames_implausible + 1)
        self._errors.set(ErrorFlag.IMPLAUSIBLE_STEP)
        self._health.degrade(Reason.IMPLAUSIBLE_STEP)

    def _mailbox_dropped(self) -> bool:
        """The mailbox dropped frames (any, or an overrun) after the last accepted encoder
        frame and before this tick's frames (on_frame reads it in line, once a frame)."""
        return self._overflows_at_accept != self._health.overflows_before

    def _step_periods(self, advance: int) -> int:
        """``sampledoubt.step_periods`` of this frame's ``advance`` (``_counter_advance``)."""
        return step_periods(advance, self._periods_since_sample, self._tick_late)

    def step_bounds(self) -> tuple[int, int]:
        """Per wheel, the most counts one encoder period can hold at ``max_wheel_speed_mm_s``:
        ceil(v_max * T / travel per count) + 1 (a count edge may fall either side of a sample).
        Configuration time: a 128-bit muldiv, then u64 division."""
        c = self._odometry.consts
        travel_q48_m = muldiv_round_u64(
            self.max_wheel_speed_mm_s * ENCODER_PERIOD_US, 1 << 48, 1_000_000_000, self._errors
        )
        return (
            (travel_q48_m + c.m_per_count_left_q48_m - 1) // c.m_per_count_left_q48_m + 1,
            (travel_q48_m + c.m_per_count_right_q48_m - 1) // c.m_per_count_right_q48_m + 1,
        )

    def _plausible(self, prev: Counts | None, counts: Counts, periods: int) -> bool:
        """True when each wheel moved at most ``periods`` times its per-period bound (u64: at
        most 2^16 * 2^32) since ``prev`` (None: nothing to compare, plausible)."""
        if prev is None:
            return True
        # wrap_signed(now - prev, bits) in line: (int16_t)(uint16_t) or (int32_t)(uint32_t)
        half = self._count_half
        mask = half + half - 1
        d_left = ((counts[0] - prev[0] + half) & mask) - half
        d_right = ((counts[1] - prev[1] + half) & mask) - half
        left_max, right_max = self._max_counts_per_period
        bound_left, bound_right = periods * left_max, periods * right_max  # |d| <= bound
        return -bound_left <= d_left <= bound_left and -bound_right <= d_right <= bound_right

    def _on_implausible(self, counter: int, wire: Counts, counts: Counts) -> None:
        """Refuse the step (DEGRADED, IMPLAUSIBLE_STEP); ``RESYNC_FRAMES`` refused frames in a row
        that are plausible among themselves are a counter restart (COUNTER_RESET): re-prime on
        the first of them and integrate from there, never the jump."""
        self.frames_implausible = wrap_u32(self.frames_implausible + 1)
        self._errors.set(ErrorFlag.IMPLAUSIBLE_STEP)
        self._health.degrade(Reason.IMPLAUSIBLE_STEP)
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

    def _restart_counters(self, counter: int, wire: Counts, counts: Counts) -> None:
        """The encoder counters restarted: prime on the first consistent frame, integrate from it
        up to ``counts`` (its periods from the COUNTER advance)."""
        first = self._resync_first
        if first is None:
            return
        self._errors.set(ErrorFlag.COUNTER_RESET)
        self._health.degrade(Reason.COUNTER_RESET)
        self._resync_first = None
        self._resync_frames = 0
        self._odometry.unprime()
        self._odometry.step_counts(first[0], first[1])
        self._enc_prev_counter = None
        self._this_step_periods = ((counter - first[2]) & COUNTER_MASK) or COUNTER_VALUES
        self._accept(counter, wire, counts)

    def _controller_restarted(self, uptime: int, wire: Counts, counter: int) -> bool:
        """True when ``uptime`` (this frame's CTRL_UPTIME, u4) is below what the last accepted
        frame's has aged to since (``_aged_uptime``; ``counter``: this frame's COUNTER), both
        reported (non-zero), and ``wire`` (its counts) near enough 0 for that age: the
        controller restarted, its counters from 0."""
        prev = self._uptime_prev
        if uptime == 0 or prev == 0 or uptime >= self._aged_uptime(prev, counter):  # aged >= prev
            return False
        return self._young_counts(wire, uptime)

    def _aged_uptime(self, prev: int, counter: int) -> int:
        """``restartage.aged_uptime`` of ``prev`` (the last accepted frame's CTRL_UPTIME, u4)
        now; ``counter``: this frame's COUNTER (the E2E successor of the last one's may have
        waited behind the silence: ``prev``, as after lost time or mailbox drops)."""
        successor = counter == ((self.enc_counter + 1) & COUNTER_MASK)
        unknown = successor or self._clock.time_lost_now or self._mailbox_dropped()
        return aged_uptime(prev, self.periods_since_frame, self._tick_late, unknown)

    def _young_counts(self, wire: Counts, uptime: int) -> bool:
        """``restartage.young_counts`` of ``wire`` for a controller ``uptime`` s old."""
        bits = min(self._odometry.consts.counter_bits, WIRE_COUNTER_BITS)
        return young_counts(wire, uptime, bits, self._max_counts_per_period)

    def _release_held(self, counter: int, wire: Counts, counts: Counts) -> Counts:
        """The frame after a held one (``counter``, ``wire``, ``counts`` from the last accepted
        frame; ``_uptime_now`` its CTRL_UPTIME): if it confirms the held frame
        (``RestartHold.confirms``, its counts young), re-prime on the held frame and return
        this frame's counts from it; else refuse the held frame and return ``counts``."""
        hold = self._hold
        hold.held = False
        uptime = self._uptime_now
        bits = WIRE_COUNTER_BITS if self._wide_counters else self._counter_bits
        if not hold.confirms(counter, wire, uptime, bits, self._max_counts_per_period) or (
            not self._young_counts(wire, uptime)
        ):
            self._refuse_unused_bits()
            return counts
        held = hold.wire
        self._uptime_now = hold.uptime
        self._reprime(hold.counter, held, self._extend_counters(held))
        self._uptime_now = uptime
        return self._extend_counters(wire)

    def _reprime(self, counter: int, wire: Counts, counts: Counts) -> None:
        """The controller restarted (CTRL_UPTIME went down): COUNTER_RESET as
        ``_restart_counters`` sets it, the odometry re-primed on this frame (its step from the
        last accepted frame, the restart's jump, is never integrated)."""
        self._errors.set(ErrorFlag.COUNTER_RESET)
        self._health.degrade(Reason.COUNTER_RESET)
        self._resync_first = None
        self._resync_frames = 0
        self._odometry.unprime()
        self._enc_prev_counter = None
        self._this_step_periods = 1
        self._accept(counter, wire, counts)

    # --- configuration ---

    def reconfigure(self, counter_bits_changed: bool) -> None:
        """After ODOM_CONFIG APPLY (the odometry already holds the new constants): new per-period
        bounds; a new counter width also forgets the counters' base (the next frame primes)."""
        if counter_bits_changed:
            self._wire_prev = None
            self._counts_prev = None
            self._hold.held = False
        self._counter_bits = self._odometry.consts.counter_bits
        self._count_half = 1 << (self._counter_bits - 1)
        self._wide_counters = self._counter_bits > WIRE_COUNTER_BITS
        self._wire_unused_mask = unused_wire_bits(self._counter_bits)
        self._max_counts_per_period = self.step_bounds()
        self._ambiguous_periods = self._least_ambiguous_periods()

    def _least_ambiguous_periods(self) -> int:
        """``ambiguity.least_ambiguous_periods`` of this robot (configuration time)."""
        bits = min(self._counter_bits, WIRE_COUNTER_BITS)
        return least_ambiguous_periods(bits, self._max_counts_per_period, STEP_PERIODS_MAX)
