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
odometry is re-primed on the first of them; or a frame whose CTRL_UPTIME is below the last
accepted one's, both non-zero: the motor controller restarted, re-primed on that frame once the
next frame confirms it, ``firmware.restarthold``; the jump itself is never integrated). The motion
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

The rooms. ``OdomEcu`` composes one part per job and runs them in the order above:
``mailbox`` (the ISR's ring), ``clock`` (firmware time), ``health`` (state, reason, watchdog),
``reception`` (the E2E gate), ``encoders`` (WHEEL_ENCODERS to an integrated step), ``twist``
(ODOM_TWIST's speeds), ``commands`` (staged set-pose/config, NAV_GOAL, ODOM_ACK), ``auth``
(SecOC hold and verify, ODOM_FRESHNESS), ``nav`` (the navigator), ``reports`` (step 5) and
``tx`` (counters and refused frames).
"""

from __future__ import annotations

from odocan.firmware import frames as fr
from odocan.firmware.auth import Auth
from odocan.firmware.clock import LOST_TIME_PERIODS as LOST_TIME_PERIODS
from odocan.firmware.clock import TICKS_PER_SECOND as TICKS_PER_SECOND
from odocan.firmware.clock import WATCHDOG_TICKS as WATCHDOG_TICKS
from odocan.firmware.clock import FirmwareClock
from odocan.firmware.commands import Commands
from odocan.firmware.config import (
    ConfigReason,
    RobotParams,
    derive_constants,
    profile_crc32,
    validate_at_speed,
)
from odocan.firmware.e2e import E2EReceiver
from odocan.firmware.encoders import MAX_WHEEL_SPEED_MM_S as MAX_WHEEL_SPEED_MM_S
from odocan.firmware.encoders import RESYNC_FRAMES as RESYNC_FRAMES
from odocan.firmware.encoders import STEP_PERIODS_MAX as STEP_PERIODS_MAX
from odocan.firmware.encoders import WIRE_COUNTER_BITS as WIRE_COUNTER_BITS
from odocan.firmware.encoders import EncoderInput
from odocan.firmware.errors import ErrorFlag, ErrorMask, Reason, State
from odocan.firmware.fixmath import U32_MAX
from odocan.firmware.hal import CanTx, FreshnessNvm
from odocan.firmware.health import RECOVERY_FRAMES as RECOVERY_FRAMES
from odocan.firmware.health import Health
from odocan.firmware.mailbox import Mailbox
from odocan.firmware.nav import NAV_PERIOD_TICKS, Navigator
from odocan.firmware.odometry import Odometry
from odocan.firmware.reception import Reception
from odocan.firmware.reports import POSE_PERIOD_TICKS as POSE_PERIOD_TICKS
from odocan.firmware.reports import STATUS_PERIOD_TICKS as STATUS_PERIOD_TICKS
from odocan.firmware.reports import Reports, frames_rejected
from odocan.firmware.secoc import SecuredCommands
from odocan.firmware.transmit import Transmitter
from odocan.firmware.twist import ENCODER_PERIOD_US as ENCODER_PERIOD_US
from odocan.firmware.twist import TWIST_SUM_MAX as TWIST_SUM_MAX
from odocan.firmware.twist import Twist
from odocan.firmware.uncertainty import PoseUncertainty

# Module constants for the tick's hot path (C: #defines and enumerators; in CPython 3.11 an enum
# attribute read costs ~0.14 us, a module attribute ~0.03 us).
_OK = State.OK
_WHEEL_ENCODERS_ID = fr.WHEEL_ENCODERS_ID
_ODOM_SET_POSE_ID = fr.ODOM_SET_POSE_ID
_ODOM_CONFIG_ID = fr.ODOM_CONFIG_ID
_NAV_GOAL_ID = fr.NAV_GOAL_ID
_ODOM_AUTH_ID = fr.ODOM_AUTH_ID


class OdomEcu:
    """The odometry ECU (node ``ODOM_MCU``): its parts, the ISRs and the tick's order."""

    def __init__(
        self,
        hal: CanTx,
        params: RobotParams,
        *,
        secoc_key: bytes | None = None,
        nvm: FreshnessNvm | None = None,
    ) -> None:
        """``params.max_wheel_speed_mm_s``: the fastest rim speed either wheel can reach (u16
        mm/s, the robot's profile); an encoder step beyond it is refused as implausible.
        ``secoc_key`` (16 bytes; None: no SecOC) and ``nvm`` (the EPOCH cell; None with a key:
        secured commands unavailable)."""
        self.errors = ErrorMask()
        self.clock = FirmwareClock()
        self.health = Health(self.errors, self.clock)
        if validate_at_speed(params, params.max_wheel_speed_mm_s) is not ConfigReason.OK:
            self.health.config_fault()
        self.params = params
        self.profile_crc = profile_crc32(params)  # u32: ODOM_STATUS PROFILE_CRC
        self.odometry = Odometry(derive_constants(params, self.errors), self.errors)
        self.mailbox = Mailbox()
        self.reception = Reception(self.errors)
        self.uncertainty = PoseUncertainty(self.health, params)
        self.twist = Twist(self.odometry, self.errors, self.uncertainty)
        self.encoders = EncoderInput(
            self.odometry,
            self.health,
            self.clock,
            self.twist,
            self.reception,
            params.max_wheel_speed_mm_s,
        )
        self.commands = Commands(self)
        self.nav = Navigator(self.errors)
        self.tx = Transmitter(hal)
        self.reports = Reports(self)
        self.frames_filtered = 0  # u32: IDs this node does not listen to
        self.auth = Auth(self, secoc_key, nvm)

    # --- ISR context -------------------------------------------------------------------------

    def isr_can_rx(self, can_id: int, data: bytes) -> None:
        """CAN receive interrupt: copy the frame into the mailbox (or count the overflow)."""
        if not self.mailbox.put(can_id, data):
            self.errors.set(ErrorFlag.MAILBOX_OVERFLOW)
            if can_id == fr.WHEEL_ENCODERS_ID:
                self.encoders.isr_dropped(data)

    def isr_rx_overrun(self) -> None:
        """CAN controller overrun interrupt: its receive FIFO dropped frames (counted as one
        mailbox overflow: the hardware flags the event, not the number)."""
        self.mailbox.count_overrun()
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
        health, clock, encoders = self.health, self.clock, self.encoders
        health.check_overflows(self.mailbox.overflows)
        periods = clock.advance(now_us)  # after: a stall's overrun is TIME_LOST
        time_lost_now = clock.time_lost_now
        if time_lost_now:
            health.time_lost()
        encoders.start_tick(periods)
        self._drain_mailbox()
        if self.auth.secoc is not None:  # C: the SecOC steps compiled in when provisioned
            self.auth.expire_held()
        self.twist.end_drain(time_lost_now, encoders.tick_budget)
        motor_cmd_due = self.clock.ticks % NAV_PERIOD_TICKS == 0 and self._navigate()
        self.reports.transmit_scheduled(motor_cmd_due)
        health.watchdog(encoders.periods_since_frame)
        clock.end_tick()

    def _drain_mailbox(self) -> None:
        """Steps 1-3: every frame in arrival order, to its handler."""
        encoder_seen = False
        mailbox = self.mailbox
        get = mailbox.get
        while mailbox.count:  # C: while (mailbox.count != 0u)
            can_id, data = get()
            if can_id == _WHEEL_ENCODERS_ID:
                encoder_seen = True
                self.encoders.on_frame(data)
            elif can_id == _ODOM_SET_POSE_ID:
                self.commands.on_set_pose(data)
            elif can_id == _ODOM_CONFIG_ID:
                self.commands.on_config(data)
            elif can_id == _NAV_GOAL_ID:
                self.commands.on_nav_goal(data)
            elif can_id == _ODOM_AUTH_ID and self.auth.secoc is not None:
                self.auth.on_auth(data)
            else:
                self.frames_filtered = (self.frames_filtered + 1) & U32_MAX  # (uint32_t)
        if not encoder_seen:
            self.encoders.no_frame()

    def _navigate(self) -> bool:
        """Step 4 (every NAV_PERIOD_TICKS): navigation from the on-board pose; True when it
        decided a MOTOR_CMD."""
        odo = self.odometry
        consts = odo.consts
        return self.nav.step(
            odo.x_q40_m,
            odo.y_q40_m,
            odo.heading_bam64,
            self.params.wheelbase_nm,
            max(consts.bam64_per_count_left, consts.bam64_per_count_right),
            self.health.state is _OK,
        )

    # --- what the board, the rig and the tests read ------------------------------------------

    @property
    def state(self) -> State:
        return self.health.state

    @property
    def reason(self) -> Reason:
        return self.health.reason

    @property
    def ticks(self) -> int:
        """u32 uptime in ticks run."""
        return self.clock.ticks

    @property
    def time_periods(self) -> int:
        """u32: 10 ms periods since reset, by the timer (ticks run or not)."""
        return self.clock.time_periods

    @property
    def periods_lost(self) -> int:
        """u32: periods the firmware did not run (stalls)."""
        return self.clock.periods_lost

    @property
    def rx_encoders(self) -> E2EReceiver:
        return self.encoders.rx

    @property
    def rx_set_pose(self) -> E2EReceiver:
        return self.commands.rx_set_pose

    @property
    def rx_config(self) -> E2EReceiver:
        return self.commands.rx_config

    @property
    def rx_nav_goal(self) -> E2EReceiver:
        return self.commands.rx_nav_goal

    @property
    def rx_auth(self) -> E2EReceiver:
        return self.auth.rx_auth

    @property
    def secoc(self) -> SecuredCommands | None:
        """The SecOC verifier and held commands (None: no key provisioned)."""
        return self.auth.secoc

    @property
    def max_wheel_speed_mm_s(self) -> int:
        """u16 mm/s: the plausibility bound in use (the configured robot's)."""
        return self.encoders.max_wheel_speed_mm_s

    @property
    def frames_implausible(self) -> int:
        """u32: WHEEL_ENCODERS refused by the plausibility bound."""
        return self.encoders.frames_implausible

    @property
    def frames_bad_length(self) -> int:
        """u32: frames not 8 bytes long (rejected before the E2E check)."""
        return self.reception.frames_bad_length

    @property
    def tx_dropped(self) -> int:
        """u32: frames the driver refused."""
        return self.tx.tx_dropped

    @property
    def frames_rejected(self) -> int:
        """Frames refused by the E2E check, for their length or as implausible (u32, wrapping)."""
        return frames_rejected(
            self.frames_bad_length,
            self.frames_implausible,
            (self.rx_encoders, self.rx_set_pose, self.rx_config, self.rx_nav_goal),
        )
