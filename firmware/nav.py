"""Navigation: a bounded path of goals, driven by turn-go-turn or go-to-goal, in fixed point.

The controller steers from the firmware's OWN odometry (``firmware.odometry``): a systematic
error of the robot (wheel diameters, wheelbase) is invisible to it and shows up only in the ground
truth. It runs in step 4 of the ECU tick every ``NAV_PERIOD_TICKS`` (20 ms, the MOTOR_CMD cycle)
and outputs wheel rim speed setpoints in mm/s.

**Path.** A ring of ``NAV_QUEUE_SLOTS`` goals (the active one at the head). A goal is staged by
NAV_GOAL X, Y, HEADING frames and committed by GO (APPEND queues it, REPLACE drops the path and
starts it now); a 17th goal is refused with QUEUE_FULL. STOP clears the path and commands 0.

**Modes** (seed 003), with the geometry of each period: dx, dy (Q40 m, goal - pose), the distance
d = isqrt(dx^2 + dy^2) (µm), the bearing phi_r = atan2(dy, dx) (BAM32) and the bearing error
e = phi_r - phi (i32 BAM32, wrapped to [-pi, pi)):

* ``TURN_GO_TURN``: TURNING rotates in place, omega = K_TURN e, until |e| < HEADING_TOL; DRIVING
  goes straight, v = K_DRIVE d cos(e) (the along-track distance: negative once the goal is
  behind, so an overshoot backs up), holding the bearing with omega = K_HOLD e while
  d >= HOLD_MIN_DISTANCE (closer, the bearing is ill-conditioned and the heading is held);
  then FINAL_TURN.
* ``GO_TO_GOAL``: DRIVING with the proportional law omega = K1 e, v = K2 d; then FINAL_TURN.
* FINAL_TURN: omega = K_TURN (heading_goal - phi) until within HEADING_TOL (skipped with
  NO_FINAL_HEADING); then REACHED. A position within POSITION_TOL ends DRIVING (and TURNING).

Limits, at the wheels whatever the wheelbase b: |v| <= V_MAX, |omega| <= OMEGA_MAX and the turn's
share of the rim speed |omega b/2| <= RIM_TURN_MAX (so omega <= 2 rad/s up to b = 0.30 m, 0.3 rad/s
at b = 2 m); the wheel speeds v -+ omega b/2 are then rate-limited to ACCEL (each wheel changes by
at most WHEEL_STEP per period). The gains keep the deceleration a P law asks for under the limits
on any robot: K_DRIVE V_MAX = 0.75 m/s^2 < ACCEL, and K_TURN RIM_TURN_MAX = 0.9 m/s^2 at the rim
(at b = 2 m the old omega-only limit asked 6 m/s^2 and the turn overshot by 0.38 rad); K1 > 4 K2
/ pi, so go-to-goal spirals in instead of circling. Turning in place (v = 0), a turn that rounds
to 0 mm/s at the rim is sent as MIN_RIM (one MOTOR_CMD step): at b = 1 cm the final turn asked
0.4 mm/s and the wheels never moved. The heading tolerance is HEADING_TOL or one encoder count's
heading step, whichever is larger (``heading_tol_bam32``): a 1 cm robot with 500-count encoders
turns in 94 mrad steps, and a tolerance finer than the odometry can see is never met.

**Commands.** While a goal is active, MOTOR_CMD every period. When a goal is reached, stopped or
aborted (the odometry left OK: encoders silent, fault), the setpoints drop to 0 at once (the motor
controller's own acceleration limit brakes) and 0 is sent for ``ZERO_CMD_PERIODS`` periods, then
the firmware falls silent (the host may command the motors). Every goal shows REACHED for one
period before the next one starts, so a host sees each goal id reach its end.
An ODOM_SET_POSE while navigating moves the robot's idea of where it is: the controller steers
from the new pose from the next period on (goals stay in the odometry frame).

Fixed-point formats: positions Q40 m (i64), distances µm (i64), angles BAM32 (i32 errors) and µrad
(i32: |e| <= 3.15e6 < 2^22), speeds mm/s and mrad/s (i32), gains in 1/1000 per second.
"""

from __future__ import annotations

from odocan.firmware.config import TWO_PI_Q60
from odocan.firmware.errors import ErrorMask
from odocan.firmware.fixmath import (
    U32_MAX,
    div_round_i64,
    i32,
    i64,
    isqrt_u64,
    mul_round_i64,
    mul_shr_round_i64,
    sat_i64,
    u32,
    u64,
    wrap_i32,
)
from odocan.firmware.frames import AckReason, NavGoal, NavGoalField, NavMode, NavState
from odocan.firmware.trig import atan2_bam32, cos_q30

NAV_PERIOD_TICKS = 2  # 20 ms at the 10 ms tick: the MOTOR_CMD cycle
NAV_PERIOD_MS = 20
NAV_QUEUE_SLOTS = 16  # goals in the path, the active one included (NAV_STATUS QUEUE_DEPTH max)
ZERO_CMD_PERIODS = 5  # zero MOTOR_CMDs after a path ends (100 ms: a lost frame cannot matter)

V_MAX_MM_S = 500  # 0.5 m/s
OMEGA_MAX_MRAD_S = 2000  # 2 rad/s
ACCEL_MM_S2 = 1000  # 1 m/s^2 at each wheel rim
WHEEL_STEP_MM_S = ACCEL_MM_S2 * NAV_PERIOD_MS // 1000  # 20 mm/s per period
POSITION_TOL_UM = 5000  # 5 mm
HEADING_TOL_BAM32 = (1 << 32) // 720  # 0.5 degree (8.73 mrad)
RIM_TURN_MAX_MM_S = 300  # |omega b/2| at most 0.3 m/s: OMEGA_MAX's rim speed at b = 0.30 m
MIN_RIM_MM_S = 1  # the least turn in place that moves the wheels: one MOTOR_CMD step
HOLD_MIN_DISTANCE_UM = 20_000  # turn-go-turn: no bearing correction within 20 mm of the goal

K_TURN_MILLI_PER_S = 3000  # turning in place: omega = 3.0/s * e
K_HOLD_MILLI_PER_S = 3000  # turn-go-turn, driving: omega = 3.0/s * e
K_DRIVE_MILLI_PER_S = 1500  # turn-go-turn, driving: v = 1.5/s * d cos(e)
K1_MILLI_PER_S = 3000  # go-to-goal (seed 003): omega = K1 (phi_r - phi)
K2_MILLI_PER_S = 1000  # go-to-goal (seed 003): v = K2 d

MICRO_PER_UNIT = 1_000_000
URAD_PER_TURN_Q20 = mul_round_i64(TWO_PI_Q60, MICRO_PER_UNIT, 40)  # 2*pi*1e6 in Q20 (< 2^43)
HALF_WHEEL_DIVISOR = 2_000_000_000  # omega[mrad/s] * b[nm] / 2e9 = omega b/2 in mm/s

_ACTIVE = (NavState.TURNING, NavState.DRIVING, NavState.FINAL_TURN)
_REACHED = NavState.REACHED  # read every period (a 3.11 enum attribute read: ~0.14 us)
_STAGED_X = 1
_STAGED_Y = 2
_STAGED_HEADING = 4


class Goal:
    """One slot of the path (a C struct in a static ring)."""

    __slots__ = ("final_turn", "goal_id", "heading_bam32", "mode", "x_q40_m", "y_q40_m")

    def __init__(self) -> None:
        self.x_q40_m: i64 = 0
        self.y_q40_m: i64 = 0
        self.heading_bam32: u32 = 0
        self.final_turn = True
        self.mode = NavMode.TURN_GO_TURN
        self.goal_id = 0  # u8


# --- the geometry, pure functions ----------------------------------------------------------


def heading_bam32_of(heading_bam64: u64) -> u32:
    """The BAM64 heading rounded to BAM32 (u32)."""
    return ((heading_bam64 + (1 << 31)) >> 32) & U32_MAX


def bearing_error_bam32(dx_q40_m: i64, dy_q40_m: i64, heading_bam32: u32) -> i32:
    """phi_r - phi: the bearing atan2(dy, dx) minus the heading, i32 BAM32 in [-pi, pi)."""
    return wrap_i32(atan2_bam32(dy_q40_m, dx_q40_m) - heading_bam32)


def distance_um(dx_q40_m: i64, dy_q40_m: i64, errors: ErrorMask) -> i64:
    """sqrt(dx^2 + dy^2) in µm (i64 >= 0), within 3 µm below 2 km, relative 2^-29 beyond.

    |dx|, |dy| are truncated to Q20 m (u64 < 2^44, error < 1 µm each); when the larger exceeds
    2^31 - 1 (2 km) both are shifted right together so that the sum of squares fits a u64
    (< 2^63); isqrt gives Q20 m (floor, < 1 µm), shifted back, then scaled to µm.
    """
    ax = (-dx_q40_m if dx_q40_m < 0 else dx_q40_m) >> 20
    ay = (-dy_q40_m if dy_q40_m < 0 else dy_q40_m) >> 20
    shift = max(max(ax, ay).bit_length() - 31, 0)
    ax >>= shift
    ay >>= shift
    d_q20_m = isqrt_u64(ax * ax + ay * ay) << shift
    return mul_shr_round_i64(d_q20_m, MICRO_PER_UNIT, 20, errors)


def _clamp(value: int, limit: int) -> int:
    """Clamp to [-limit, limit]: a design limit (no SATURATION flag)."""
    return -limit if value < -limit else min(value, limit)


def turn_rate_mrad_s(error_bam32: i32, gain_milli_per_s: int, errors: ErrorMask) -> i32:
    """omega = K e in mrad/s, clamped to +-OMEGA_MAX (e: i32 BAM32; K in 1/1000 per second).

    From the BAM32 directly, not from the rounded µrad: e K (< 2^43) times µrad per turn (Q20)
    in the 128-bit product gives omega in nrad/s, then one division by 10^6 (error <= 0.5 +
    5e-7 mrad/s)."""
    nrad_s = mul_shr_round_i64(
        wrap_i32(error_bam32) * gain_milli_per_s, URAD_PER_TURN_Q20, 52, errors
    )
    omega = div_round_i64(nrad_s, MICRO_PER_UNIT)
    return _clamp(omega, OMEGA_MAX_MRAD_S)


def speed_mm_s(distance_um_: i64, gain_milli_per_s: int) -> i32:
    """v = K d in mm/s, clamped to +-V_MAX (d: signed µm; K in 1/1000 per second)."""
    return _clamp(div_round_i64(distance_um_ * gain_milli_per_s, MICRO_PER_UNIT), V_MAX_MM_S)


def wheel_speeds_mm_s(v_mm_s: i32, omega_mrad_s: i32, wheelbase_nm: u32) -> tuple[i32, i32]:
    """(left, right) rim speeds v -+ omega b/2 in mm/s (rounded; |omega b| < 2^44), the turn's
    share clamped to +-RIM_TURN_MAX and, turning in place, at least MIN_RIM when omega != 0."""
    half_mm_s = _clamp(div_round_i64(omega_mrad_s * wheelbase_nm, HALF_WHEEL_DIVISOR),
                       RIM_TURN_MAX_MM_S)
    if v_mm_s == 0 and half_mm_s == 0 and omega_mrad_s != 0:
        half_mm_s = _clamp(omega_mrad_s, MIN_RIM_MM_S)  # omega != 0: +-MIN_RIM, its sign
    return v_mm_s - half_mm_s, v_mm_s + half_mm_s


def heading_tol_bam32(count_bam64: u64) -> u32:
    """The heading tolerance: HEADING_TOL or one encoder count's heading step (BAM64, < 2^60,
    rounded up to BAM32 by the + 1), whichever is larger (u32)."""
    return max(HEADING_TOL_BAM32, (count_bam64 >> 32) + 1)


def go_to_goal_law(dist_um: i64, bearing_error: i32, errors: ErrorMask) -> tuple[i32, i32]:
    """Seed 003: (v, omega) = (K2 d, K1 (phi_r - phi)) in (mm/s, mrad/s), each limited."""
    return (
        speed_mm_s(dist_um, K2_MILLI_PER_S),
        turn_rate_mrad_s(bearing_error, K1_MILLI_PER_S, errors),
    )


def drive_straight_law(dist_um: i64, bearing_error: i32, errors: ErrorMask) -> tuple[i32, i32]:
    """Turn-go-turn's straight leg: v = K_DRIVE d cos(e) (along the track, signed), the bearing
    held by omega = K_HOLD e while d >= HOLD_MIN_DISTANCE (0 closer)."""
    along_um = mul_shr_round_i64(dist_um, cos_q30(bearing_error & U32_MAX), 30, errors)
    omega = 0
    if dist_um >= HOLD_MIN_DISTANCE_UM:
        omega = turn_rate_mrad_s(bearing_error, K_HOLD_MILLI_PER_S, errors)
    return speed_mm_s(along_um, K_DRIVE_MILLI_PER_S), omega


def rate_limit(target_mm_s: i32, previous_mm_s: i32) -> i32:
    """The wheel setpoint moved from ``previous`` toward ``target`` by at most WHEEL_STEP."""
    return previous_mm_s + _clamp(target_mm_s - previous_mm_s, WHEEL_STEP_MM_S)


# --- the navigator -------------------------------------------------------------------------


class Navigator:
    """The path, its state machine and the wheel setpoints (runs in the ECU's thread context)."""

    __slots__ = (
        "_errors",
        "_head",
        "_ring",
        "_staged",
        "_staged_heading_bam16",
        "_staged_x_100um",
        "_staged_y_100um",
        "_zero_periods",
        "changed",
        "depth",
        "distance_um",
        "goal_id",
        "heading_error_bam32",
        "heading_tol_bam32",
        "left_mm_s",
        "right_mm_s",
        "state",
    )

    def __init__(self, errors: ErrorMask) -> None:
        self._errors = errors
        self._ring = [Goal() for _ in range(NAV_QUEUE_SLOTS)]
        self._head = 0
        self.depth = 0  # goals in the ring (the active one included)
        self.state = NavState.IDLE
        self.goal_id = 0  # u8: the active or last goal
        self.distance_um: i64 = 0
        self.heading_error_bam32: i32 = 0
        self.heading_tol_bam32: u32 = HEADING_TOL_BAM32  # from the geometry, every period
        self.left_mm_s: i32 = 0  # the last setpoints (the rate limiter's memory)
        self.right_mm_s: i32 = 0
        self.changed = True  # STATE or GOAL_ID changed since NAV_STATUS was last sent
        self._zero_periods = 0
        self._staged = 0  # bit mask of _STAGED_*
        self._staged_x_100um = 0
        self._staged_y_100um = 0
        self._staged_heading_bam16 = 0

    # --- requests (NAV_GOAL frames, from the drain step) -----------------------------------

    def request(self, frame: NavGoal, running: bool) -> AckReason:
        """Handle one NAV_GOAL frame; the reason of its ODOM_ACK. ``running``: odometry OK."""
        field = frame.field
        if field == NavGoalField.X:
            self._staged_x_100um = frame.value
            self._staged |= _STAGED_X
        elif field == NavGoalField.Y:
            self._staged_y_100um = frame.value
            self._staged |= _STAGED_Y
        elif field == NavGoalField.HEADING:
            self._staged_heading_bam16 = frame.value
            self._staged |= _STAGED_HEADING
        elif field == NavGoalField.STOP:
            self._staged = 0
            self._clear_path()
            self._halt(NavState.STOPPED)
        elif field == NavGoalField.GO:
            return self._go(frame, running)
        else:
            return AckReason.UNKNOWN_FIELD
        return AckReason.OK

    def _go(self, frame: NavGoal, running: bool) -> AckReason:
        """GO: validate the staged goal, then append it or replace the path with it."""
        staged = self._staged
        self._staged = 0
        needed = _STAGED_X | _STAGED_Y | (0 if frame.no_final_heading else _STAGED_HEADING)
        if staged & needed != needed:
            return AckReason.INCOMPLETE
        if frame.mode > NavMode.GO_TO_GOAL:
            return AckReason.OUT_OF_RANGE
        if not running:
            return AckReason.BUSY
        if frame.append:
            if self.depth == NAV_QUEUE_SLOTS:
                return AckReason.QUEUE_FULL
        else:
            self._clear_path()
        self._enqueue(frame)
        if not frame.append or self.state not in _ACTIVE:
            self._start()
        return AckReason.OK

    def _enqueue(self, frame: NavGoal) -> None:
        goal = self._ring[(self._head + self.depth) % NAV_QUEUE_SLOTS]
        goal.x_q40_m = q40_from_100um(self._staged_x_100um)
        goal.y_q40_m = q40_from_100um(self._staged_y_100um)
        goal.heading_bam32 = (self._staged_heading_bam16 << 16) & U32_MAX
        goal.final_turn = not frame.no_final_heading
        goal.mode = NavMode(frame.mode)
        goal.goal_id = frame.goal_id
        self.depth += 1

    def _clear_path(self) -> None:
        self._head = 0
        self.depth = 0

    # --- the state machine ------------------------------------------------------------------

    def _set_state(self, state: NavState) -> None:
        if state is not self.state:
            self.state = state
            self.changed = True

    def _start(self) -> None:
        """Make the head of the path the active goal."""
        goal = self._ring[self._head]
        if goal.goal_id != self.goal_id:
            self.goal_id = goal.goal_id
            self.changed = True
        self._zero_periods = 0
        self._set_state(NavState.TURNING if goal.mode is NavMode.TURN_GO_TURN else NavState.DRIVING)

    def _halt(self, state: NavState) -> None:
        """End the active goal (or the idle wait) in ``state``: setpoints 0, then zero commands."""
        self._set_state(state)
        self.left_mm_s = 0
        self.right_mm_s = 0
        self._zero_periods = ZERO_CMD_PERIODS

    def _finish(self) -> None:
        """The active goal is reached: drop it from the path."""
        self._head = (self._head + 1) % NAV_QUEUE_SLOTS
        self.depth -= 1
        self._halt(NavState.REACHED)

    def step(
        self,
        x_q40_m: i64,
        y_q40_m: i64,
        heading_bam64: u64,
        wheelbase_nm: u32,
        count_bam64: u64,
        running: bool,
    ) -> bool:
        """One control period (step 4, every NAV_PERIOD_TICKS). True when a MOTOR_CMD with
        (``left_mm_s``, ``right_mm_s``) is to be sent this period. ``count_bam64``: the larger
        wheel's heading step per encoder count; ``running``: odometry OK."""
        self.heading_tol_bam32 = heading_tol_bam32(count_bam64)
        if self.state in _ACTIVE and not running:
            self._clear_path()
            self._halt(NavState.ABORTED)
        elif self.state is _REACHED and self.depth:
            if running:
                self._start()
            else:
                self._clear_path()
                self._halt(NavState.ABORTED)
        if self.state in _ACTIVE:
            v_mm_s, omega_mrad_s = self._control(x_q40_m, y_q40_m, heading_bam32_of(heading_bam64))
            if self.state in _ACTIVE:
                left, right = wheel_speeds_mm_s(v_mm_s, omega_mrad_s, wheelbase_nm)
                self.left_mm_s = rate_limit(left, self.left_mm_s)
                self.right_mm_s = rate_limit(right, self.right_mm_s)
                return True
        if self._zero_periods > 0:
            self._zero_periods -= 1
            return True
        return False

    def _control(self, x_q40_m: i64, y_q40_m: i64, heading_bam32: u32) -> tuple[i32, i32]:
        """The phase transitions, then the active phase's (v mm/s, omega mrad/s)."""
        goal = self._ring[self._head]
        e = self._errors
        dx = sat_i64(goal.x_q40_m - x_q40_m, e)
        dy = sat_i64(goal.y_q40_m - y_q40_m, e)
        dist_um = distance_um(dx, dy, e)
        bearing_error = bearing_error_bam32(dx, dy, heading_bam32)
        final_error = wrap_i32(goal.heading_bam32 - heading_bam32)
        self.distance_um = dist_um
        if self.state is NavState.TURNING and abs(bearing_error) < self.heading_tol_bam32:
            self._set_state(NavState.DRIVING)
        if self.state is not NavState.FINAL_TURN and dist_um < POSITION_TOL_UM:
            self._set_state(NavState.FINAL_TURN)
        if self.state is NavState.FINAL_TURN:
            self.heading_error_bam32 = final_error if goal.final_turn else 0
            if abs(self.heading_error_bam32) < self.heading_tol_bam32:
                self._finish()
                return 0, 0
            return 0, turn_rate_mrad_s(final_error, K_TURN_MILLI_PER_S, e)
        self.heading_error_bam32 = bearing_error
        if self.state is NavState.TURNING:
            return 0, turn_rate_mrad_s(bearing_error, K_TURN_MILLI_PER_S, e)
        if goal.mode is NavMode.GO_TO_GOAL:
            return go_to_goal_law(dist_um, bearing_error, e)
        return drive_straight_law(dist_um, bearing_error, e)


def q40_from_100um(value_100um: i32) -> i64:
    """0.1 mm units (i32) to Q40 metres (i64), exactly rounded (NAV_GOAL and ODOM_SET_POSE's
    X/Y, ``firmware.commands``), without a 72-bit intermediate: whole metres shifted, plus the
    remainder (< 10^4, so ``r << 40`` < 2^54) divided."""
    metres, remainder_100um = divmod(value_100um, 10_000)  # floor semantics, remainder >= 0
    return (metres << 40) + div_round_i64(remainder_100um << 40, 10_000)
