"""Navigation (firmware.nav): the fixed-point laws against float64, the state machine, the ECU's
frames decoded by cantools, and closed-loop lockstep runs judged by the on-board pose (on the
bus) and by the ground truth.

The closed-loop harness is the rig's lockstep order without a scenario driver: three python-can
``virtual`` bus handles on a channel of their own (sim, firmware, host), the motor controller, the
truth, the firmware board, and the host sending NAV_GOAL frames and reading everything back.
"""

from __future__ import annotations

import itertools
import math
from pathlib import Path
from typing import Any

import can
import cantools
import pytest
from hypothesis import given
from hypothesis import strategies as st

from odocan.firmware import frames as fr
from odocan.firmware import nav
from odocan.firmware.errors import ErrorMask
from odocan.firmware.fixmath import I64_MAX, I64_MIN, isqrt_u64
from odocan.firmware.frames import AckReason, NavGoalField, NavMode, NavState
from odocan.sim.board import TICK_S
from odocan.sim.errors import ErrorModel
from odocan.sim.pose import wrap_angle
from odocan.sim.rig import LockstepRig, RigConfig
from odocan.sim.robot import load
from tests import host_frames as hf


def _load_dbc() -> cantools.database.can.Database:
    db = cantools.database.load_file(
        Path(__file__).resolve().parents[1] / "dbc" / "odocan.dbc", strict=True
    )
    assert isinstance(db, cantools.database.can.Database)
    return db


def state(n: nav.Navigator) -> NavState:
    """The navigator's state now: a call, so mypy does not keep ``n.state`` narrowed to what an
    earlier assert saw across the steps that change it."""
    return n.state


DB = _load_dbc()
TWO_PI = 2 * math.pi
Q40 = float(1 << 40)
PMIR_WHEELBASE_NM = 300_000_000
PMIR_COUNT_BAM64 = (1 << 64) // 2000  # one count's heading step: r / (N b) = 0.075 / 150 turn
TOL_M = nav.POSITION_TOL_UM * 1e-6  # 5 mm
TOL_RAD = nav.HEADING_TOL_BAM32 * TWO_PI / 2**32  # 0.5 degree
# The ground truth of the error-free robot differs from the on-board pose by the encoders'
# quantisation (pmir: 0.94 mm of wheel travel and 0.18 degree of heading per count): a
# measured worst case of 3.6 mm and 0.41 degree from the goal over the runs below.
TRUTH_TOL_M = 0.008
TRUTH_TOL_RAD = math.radians(0.75)


def bam32_rad(angle_bam32: int) -> float:
    return angle_bam32 * TWO_PI / 2**32


# --- isqrt and the geometry against float64 ----------------------------------------------------


@given(st.integers(0, (1 << 64) - 1))
def test_isqrt_u64_is_floor_sqrt(n: int) -> None:
    r = isqrt_u64(n)
    assert r == math.isqrt(n)
    assert r * r <= n < (r + 1) * (r + 1)


def test_isqrt_u64_edges_and_every_small_value() -> None:
    assert [isqrt_u64(n) for n in range(70_000)] == [math.isqrt(n) for n in range(70_000)]
    for k in range(1, 33):
        for n in ((1 << (2 * k)) - 1, 1 << (2 * k), ((1 << k) - 1) ** 2, (1 << k) ** 2 - 1):
            if n < 1 << 64:
                assert isqrt_u64(n) == math.isqrt(n)
    assert isqrt_u64((1 << 64) - 1) == (1 << 32) - 1


def to_q40(metres: float) -> int:
    return round(metres * Q40)


@given(st.floats(-2000, 2000), st.floats(-2000, 2000))
def test_distance_within_3_um_below_2_km(dx_m: float, dy_m: float) -> None:
    dx, dy = to_q40(dx_m), to_q40(dy_m)
    got_um = nav.distance_um(dx, dy, ErrorMask())
    assert abs(got_um - math.hypot(dx / Q40, dy / Q40) * 1e6) <= 3.0


@given(st.integers(I64_MIN, I64_MAX), st.integers(I64_MIN, I64_MAX))
def test_distance_relative_2e_29_over_the_whole_i64_plane(dx: int, dy: int) -> None:
    errors = ErrorMask()
    got_um = nav.distance_um(dx, dy, errors)
    want_um = math.hypot(dx / Q40, dy / Q40) * 1e6
    assert abs(got_um - want_um) <= 3.0 + want_um * 2**-29
    assert errors.bits == 0


@given(st.floats(-10, 10), st.floats(-10, 10), st.integers(0, (1 << 32) - 1))
def test_bearing_error_against_float(dx_m: float, dy_m: float, heading_bam32: int) -> None:
    dx, dy = to_q40(dx_m), to_q40(dy_m)
    got = nav.bearing_error_bam32(dx, dy, heading_bam32)
    assert -(2**31) <= got < 2**31
    want = wrap_angle(math.atan2(dy, dx) - bam32_rad(heading_bam32))
    assert abs(wrap_angle(bam32_rad(got) - want)) <= 2e-9  # atan2's 0.5 LSB + float noise


@given(st.integers(0, (1 << 64) - 1))
def test_heading_bam32_is_the_rounded_bam64(heading_bam64: int) -> None:
    got = nav.heading_bam32_of(heading_bam64)
    assert abs(wrap_angle(bam32_rad(got) - heading_bam64 * TWO_PI / 2**64)) <= math.pi / 2**32


# --- the control laws ---------------------------------------------------------------------------


def clamp(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))


@given(st.integers(-(2**31), 2**31 - 1), st.sampled_from([1, 1000, 3000, 4000]))
def test_turn_rate_is_k_times_error_limited(error_bam32: int, gain_milli: int) -> None:
    want = clamp(gain_milli / 1000 * bam32_rad(error_bam32) * 1000, nav.OMEGA_MAX_MRAD_S)
    assert abs(nav.turn_rate_mrad_s(error_bam32, gain_milli, ErrorMask()) - want) <= 0.5 + 1e-6


@given(st.integers(-(10**13), 10**13), st.sampled_from([1, 1000, 1500]))
def test_speed_is_k_times_distance_limited(dist_um: int, gain_milli: int) -> None:
    want = clamp(gain_milli / 1000 * dist_um / 1000, nav.V_MAX_MM_S)
    assert abs(nav.speed_mm_s(dist_um, gain_milli) - want) <= 0.5


@given(st.integers(0, 10**8), st.integers(-(2**31), 2**31 - 1))
def test_go_to_goal_law_is_seed_003(dist_um: int, bearing_error: int) -> None:
    """omega = K1 (phi_r - phi), v = K2 * distance, each within its limit."""
    v, omega = nav.go_to_goal_law(dist_um, bearing_error, ErrorMask())
    k1, k2 = nav.K1_MILLI_PER_S / 1000, nav.K2_MILLI_PER_S / 1000
    assert abs(v - clamp(k2 * dist_um / 1000, nav.V_MAX_MM_S)) <= 0.5
    want_omega = clamp(k1 * bam32_rad(bearing_error) * 1000, nav.OMEGA_MAX_MRAD_S)
    assert abs(omega - want_omega) <= 0.5 + 1e-6


@given(st.integers(0, 10**8), st.integers(-(2**31), 2**31 - 1))
def test_drive_straight_law_goes_along_the_track(dist_um: int, bearing_error: int) -> None:
    v, omega = nav.drive_straight_law(dist_um, bearing_error, ErrorMask())
    e = bam32_rad(bearing_error)
    along_mm = dist_um / 1000 * math.cos(e)
    assert abs(v - clamp(nav.K_DRIVE_MILLI_PER_S / 1000 * along_mm, nav.V_MAX_MM_S)) <= 0.5 + 1e-3
    if dist_um < nav.HOLD_MIN_DISTANCE_UM:
        assert omega == 0
    else:
        want = clamp(nav.K_HOLD_MILLI_PER_S / 1000 * e * 1000, nav.OMEGA_MAX_MRAD_S)
        assert abs(omega - want) <= 0.5 + 1e-6


@given(st.integers(-2000, 2000), st.integers(-2000, 2000), st.integers(10**7, 4 * 10**9))
def test_wheel_speeds_are_v_minus_plus_omega_half_b(v: int, omega: int, wheelbase_nm: int) -> None:
    """The turn's share omega b/2 is limited to 0.3 m/s at the rims (any wheelbase); turning in
    place, a nonzero omega moves the rims by at least one MOTOR_CMD step (1 mm/s)."""
    left, right = nav.wheel_speeds_mm_s(v, omega, wheelbase_nm)
    half = clamp(omega / 1000 * wheelbase_nm * 1e-9 / 2 * 1000, 300.0)
    if v == 0 and omega != 0 and abs(half) < 0.5:
        assert right == (1 if omega > 0 else -1)
    else:
        assert abs(right - (v + half)) <= 0.5
    assert abs(left - (v - half)) <= 0.5 or v == 0
    assert left + right == 2 * v  # the same rounded half on both sides: no drift of v


@given(st.integers(-3000, 3000), st.integers(-3000, 3000))
def test_rate_limit_ramps_linearly_to_the_target(target: int, start: int) -> None:
    """Closed form: after n periods the setpoint is start + sign * min(n * step, |target - start|),
    i.e. ACCEL = 20 mm/s per 20 ms = 1 m/s^2."""
    assert nav.WHEEL_STEP_MM_S * 1000 // nav.NAV_PERIOD_MS == nav.ACCEL_MM_S2
    speed = start
    sign = 1 if target >= start else -1
    for n in range(1, 400):
        speed = nav.rate_limit(target, speed)
        assert speed == start + sign * min(n * nav.WHEEL_STEP_MM_S, abs(target - start))


def test_gains_respect_the_limits_they_must() -> None:
    """The decelerations the P laws ask for stay under ACCEL (module docstring), and K1 > 4 K2/pi
    (go-to-goal spirals in: its turning radius at e = pi/2 stays below d/2)."""
    assert nav.K_DRIVE_MILLI_PER_S * nav.V_MAX_MM_S // 1000 < nav.ACCEL_MM_S2
    assert nav.K2_MILLI_PER_S * nav.V_MAX_MM_S // 1000 < nav.ACCEL_MM_S2
    rim_m_s = min(nav.OMEGA_MAX_MRAD_S * PMIR_WHEELBASE_NM * 1e-12 / 2, 0.3)
    assert nav.K_TURN_MILLI_PER_S / 1000 * rim_m_s * 1000 < nav.ACCEL_MM_S2
    assert nav.K_TURN_MILLI_PER_S * nav.RIM_TURN_MAX_MM_S // 1000 < nav.ACCEL_MM_S2  # any b
    assert 4 * nav.K2_MILLI_PER_S / math.pi < nav.K1_MILLI_PER_S


# --- the state machine, with a scripted pose -------------------------------------------------


def goal_frames(
    x_m: float,
    y_m: float,
    heading_deg: float | None,
    *,
    mode: NavMode = NavMode.TURN_GO_TURN,
    goal_id: int = 1,
    append: bool = True,
) -> list[fr.NavGoal]:
    """The NAV_GOAL records that stage and commit one goal (no HEADING when None)."""
    records = [
        fr.NavGoal(0, NavGoalField.X, round(x_m * 1e4), 0, 0, 0, 0),
        fr.NavGoal(0, NavGoalField.Y, round(y_m * 1e4), 0, 0, 0, 0),
    ]
    if heading_deg is not None:
        bam16 = round(heading_deg / 360 * 65536) & 0xFFFF
        records.append(fr.NavGoal(0, NavGoalField.HEADING, bam16, 0, 0, 0, 0))
    no_final = int(heading_deg is None)
    records.append(fr.NavGoal(0, NavGoalField.GO, 0, mode, int(append), no_final, goal_id))
    return records


def submit(navigator: nav.Navigator, records: list[fr.NavGoal], running: bool = True) -> AckReason:
    reasons = [navigator.request(r, running) for r in records]
    assert set(reasons[:-1]) <= {AckReason.OK}
    return reasons[-1]


class Pose:
    """A scripted on-board pose (metres, degrees) fed to ``Navigator.step``."""

    def __init__(self) -> None:
        self.x_m = 0.0
        self.y_m = 0.0
        self.heading_deg = 0.0

    def step(self, navigator: nav.Navigator, running: bool = True) -> bool:
        heading_bam64 = round(self.heading_deg / 360 * 2**64) % 2**64
        return navigator.step(
            to_q40(self.x_m), to_q40(self.y_m), heading_bam64, PMIR_WHEELBASE_NM,
            PMIR_COUNT_BAM64, running,
        )


def test_turn_go_turn_walks_through_every_state() -> None:
    n, pose = nav.Navigator(ErrorMask()), Pose()
    assert state(n) is NavState.IDLE
    assert not pose.step(n)  # idle: no MOTOR_CMD
    assert submit(n, goal_frames(0.0, 1.0, 180.0, goal_id=7)) is AckReason.OK
    assert (n.state, n.goal_id, n.depth) == (NavState.TURNING, 7, 1)
    assert pose.step(n)
    assert n.right_mm_s == nav.WHEEL_STEP_MM_S == -n.left_mm_s  # turning left, rate-limited
    assert abs(bam32_rad(n.heading_error_bam32) - math.pi / 2) < 1e-8
    pose.heading_deg = 89.8  # within 0.5 degree of the bearing: drive
    assert pose.step(n)
    assert state(n) is NavState.DRIVING
    pose.y_m = 0.996  # 4 mm short: the final turn
    assert pose.step(n)
    assert state(n) is NavState.FINAL_TURN
    assert n.distance_um == pytest.approx(4000, abs=3)
    pose.heading_deg = 179.6
    assert pose.step(n)
    assert state(n) is NavState.REACHED
    assert (n.left_mm_s, n.right_mm_s, n.depth) == (0, 0, 0)
    sent = [pose.step(n) for _ in range(10)]
    assert sent == [True] * (nav.ZERO_CMD_PERIODS - 1) + [False] * (11 - nav.ZERO_CMD_PERIODS)
    assert (n.left_mm_s, n.right_mm_s, n.state) == (0, 0, NavState.REACHED)


def test_go_to_goal_starts_driving_and_skips_the_final_turn_without_heading() -> None:
    n, pose = nav.Navigator(ErrorMask()), Pose()
    assert submit(n, goal_frames(1.0, 1.0, None, mode=NavMode.GO_TO_GOAL)) is AckReason.OK
    assert state(n) is NavState.DRIVING
    for k in range(1, 40):  # a fixed pose: the wheels ramp to the law's setpoints, then hold
        pose.step(n)
        v, omega = nav.go_to_goal_law(n.distance_um, n.heading_error_bam32, ErrorMask())
        left, right = nav.wheel_speeds_mm_s(v, omega, PMIR_WHEELBASE_NM)
        step = k * nav.WHEEL_STEP_MM_S
        assert (n.left_mm_s, n.right_mm_s) == (clamp(left, step), clamp(right, step))
    pose.x_m, pose.y_m, pose.heading_deg = 0.998, 1.002, 123.0
    assert pose.step(n)
    assert state(n) is NavState.REACHED
    assert n.heading_error_bam32 == 0


def test_the_next_goal_starts_one_period_after_reached() -> None:
    n, pose = nav.Navigator(ErrorMask()), Pose()
    submit(n, goal_frames(0.001, 0.0, None, goal_id=1))
    submit(n, goal_frames(1.0, 0.0, None, goal_id=2))
    assert n.depth == 2
    pose.step(n)
    assert (n.state, n.goal_id, n.depth) == (NavState.REACHED, 1, 1)
    pose.step(n)
    assert (n.state, n.goal_id, n.depth) == (NavState.DRIVING, 2, 1)  # already on its bearing


def test_requests_are_validated() -> None:
    n = nav.Navigator(ErrorMask())
    assert submit(n, goal_frames(1.0, 0.0, None)[:1] + goal_frames(1, 0, None)[-1:]) is (
        AckReason.INCOMPLETE  # Y missing
    )
    go_with_heading = fr.NavGoal(0, NavGoalField.GO, 0, 0, 1, 0, 1)
    assert submit(n, [*goal_frames(1.0, 0.0, None)[:2], go_with_heading]) is AckReason.INCOMPLETE
    bad_mode = fr.NavGoal(0, NavGoalField.GO, 0, 7, 1, 1, 1)
    assert submit(n, [*goal_frames(1.0, 0.0, None)[:2], bad_mode]) is AckReason.OUT_OF_RANGE
    assert submit(n, goal_frames(1.0, 0.0, None), running=False) is AckReason.BUSY
    assert n.request(fr.NavGoal(0, 9, 0, 0, 0, 0, 0), True) is AckReason.UNKNOWN_FIELD
    assert n.state is NavState.IDLE
    assert n.depth == 0
    # GO consumed the staged fields: a bare GO after a refused one is INCOMPLETE
    assert n.request(goal_frames(1.0, 0.0, None)[-1], True) is AckReason.INCOMPLETE


def test_queue_full_replace_and_stop() -> None:
    n, pose = nav.Navigator(ErrorMask()), Pose()
    for k in range(nav.NAV_QUEUE_SLOTS):
        assert submit(n, goal_frames(k + 1.0, 0.0, None, goal_id=k)) is AckReason.OK
    assert n.depth == nav.NAV_QUEUE_SLOTS == fr.NAV_QUEUE_DEPTH_MAX
    assert submit(n, goal_frames(9.0, 9.0, None, goal_id=99)) is AckReason.QUEUE_FULL
    assert n.depth == nav.NAV_QUEUE_SLOTS
    assert n.goal_id == 0
    for _ in range(5):
        pose.step(n)
    assert n.left_mm_s > 0
    frames = goal_frames(0.0, -1.0, None, goal_id=50, append=False)
    assert submit(n, frames) is AckReason.OK
    assert (n.goal_id, n.depth, n.state) == (50, 1, NavState.TURNING)
    assert n.request(fr.NavGoal(0, NavGoalField.STOP, 0, 0, 0, 0, 0), True) is AckReason.OK
    assert (n.state, n.depth, n.left_mm_s, n.right_mm_s) == (NavState.STOPPED, 0, 0, 0)
    assert [pose.step(n) for _ in range(8)] == [True] * nav.ZERO_CMD_PERIODS + [False] * 3


def test_odometry_loss_aborts_the_path() -> None:
    n, pose = nav.Navigator(ErrorMask()), Pose()
    submit(n, goal_frames(1.0, 0.0, None))
    submit(n, goal_frames(2.0, 0.0, None, goal_id=2))
    pose.step(n)
    assert pose.step(n, running=False)
    assert (n.state, n.depth, n.left_mm_s, n.right_mm_s) == (NavState.ABORTED, 0, 0, 0)


# --- the ECU: frames in, frames out, decoded by cantools ---------------------------------------


class _Heard(can.Listener):
    def __init__(self, owner: LockstepNav) -> None:
        self.owner = owner

    def on_message_received(self, msg: can.Message) -> None:
        self.owner.heard(msg)


class LockstepNav:
    """The closed-loop lockstep rig (no scenario driver) on a private channel, with every frame
    the host hears decoded by cantools and the truth taken when a goal shows REACHED."""

    _channels = itertools.count()

    def __init__(self, errors: ErrorModel | None = None, robot: str = "pmir") -> None:
        config = RigConfig(
            load(robot),
            "exact",
            None,
            errors=errors or ErrorModel(),
            channel=f"test_nav_{next(self._channels)}",
        )
        self.rig = LockstepRig(config, [_Heard(self)])
        self.board = self.rig.board
        self.vehicle = self.rig.vehicle
        self.clock = self.rig.clock
        self.frames: list[tuple[int, str, dict[str, Any]]] = []  # (tick, message, signals)
        self.truth_at_reached: dict[int, tuple[float, float, float]] = {}
        self._counter = itertools.count()
        self._scratch = ErrorMask()

    @property
    def ticks(self) -> int:
        return self.rig.ticks

    @ticks.setter
    def ticks(self, value: int) -> None:
        self.rig.ticks = value

    def close(self) -> None:
        self.rig.close()

    def step(self) -> None:
        """One 10 ms tick of the rig."""
        self.rig.step()

    def heard(self, msg: can.Message) -> None:
        """A frame on the host's bus: decoded and kept."""
        name = DB.get_message_by_frame_id(msg.arbitration_id).name
        decoded = DB.decode_message(msg.arbitration_id, bytes(msg.data), decode_choices=False)
        signals: dict[str, Any] = dict(decoded)  # type: ignore[arg-type]
        self.frames.append((self.ticks, name, signals))
        if name == "NAV_STATUS" and signals["STATE"] == NavState.REACHED:
            pose = self.vehicle.truth()
            self.truth_at_reached[signals["GOAL_ID"]] = (pose.x_m, pose.y_m, pose.heading_rad)

    def run(self, seconds: float) -> None:
        self.rig.run(seconds)

    def send(self, data: bytes) -> None:
        self.rig.send(fr.NAV_GOAL_ID, data)

    def goal(self, x_m: float, y_m: float, heading_deg: float | None, **kw: Any) -> None:
        """Stage and commit one goal (four frames, or three without a heading), then one tick."""
        for r in goal_frames(x_m, y_m, heading_deg, **kw):
            counter = next(self._counter)
            if r.field == NavGoalField.GO:
                args = (r.mode, r.append, r.no_final_heading, r.goal_id)
                self.send(hf.pack_nav_goal_go(counter, *args, self._scratch))
            else:
                self.send(hf.pack_nav_goal(counter, r.field, r.value, self._scratch))
        self.step()

    def stop(self) -> None:
        self.send(hf.pack_nav_goal(next(self._counter), NavGoalField.STOP, 0, self._scratch))
        self.step()

    def run_until_done(self, limit_s: float = 60.0) -> None:
        """Until the path is empty and no goal is active, then 1 s for the robot to settle."""
        navigator = self.board.ecu.nav
        for _ in range(round(limit_s / TICK_S)):
            self.step()
            if navigator.depth == 0 and navigator.state not in nav._ACTIVE:
                break
        self.run(1.0)

    def of(self, name: str) -> list[tuple[int, dict[str, Any]]]:
        return [(t, s) for t, n, s in self.frames if n == name]

    def onboard_pose(self) -> tuple[float, float, float]:
        """The last on-board pose from ODOM_POSE_X / ODOM_POSE_Y, as decoded on the bus."""
        pose_x = self.of("ODOM_POSE_X")[-1][1]
        pose_y = self.of("ODOM_POSE_Y")[-1][1]
        return pose_x["X"], pose_y["Y"], pose_x["HEADING"]

    def reached_ids(self) -> list[int]:
        """The goals that reached REACHED, in order (each once: the status repeats every 100 ms)."""
        ids = []
        previous = None
        for _, s in self.of("NAV_STATUS"):
            now = (s["STATE"], s["GOAL_ID"])
            if now != previous and s["STATE"] == NavState.REACHED:
                ids.append(s["GOAL_ID"])
            previous = now
        return ids


@pytest.fixture
def rig() -> Any:
    r = LockstepNav()
    r.run(0.1)  # the odometry is running
    yield r
    r.close()


SQUARE = [(1.0, 0.0, 90.0), (1.0, 1.0, 180.0), (0.0, 0.0, 0.0)]


def truth_pose(r: LockstepNav) -> tuple[float, float, float]:
    pose = r.vehicle.truth()
    return pose.x_m, pose.y_m, pose.heading_rad


def pose_error(
    pose: tuple[float, float, float], goal: tuple[float, float, float]
) -> tuple[float, float]:
    return math.hypot(pose[0] - goal[0], pose[1] - goal[1]), abs(
        wrap_angle(pose[2] - math.radians(goal[2]))
    )


@pytest.mark.parametrize("mode", list(NavMode), ids=lambda m: m.name)
def test_closed_loop_path_reaches_every_goal_in_order(rig: LockstepNav, mode: NavMode) -> None:
    for goal_id, goal in enumerate(SQUARE, start=1):
        rig.goal(*goal, mode=mode, goal_id=goal_id)
    acks = rig.of("ODOM_ACK")
    assert len(acks) == 12
    assert {a["REQUEST_ID"] for _, a in acks} == {fr.NAV_GOAL_ID}
    assert {(a["RESULT"], a["REASON"]) for _, a in acks} == {(0, 0)}
    rig.run_until_done()
    assert rig.reached_ids() == [1, 2, 3]
    statuses = [s for _, s in rig.of("NAV_STATUS")]
    depths = [s["QUEUE_DEPTH"] for s in statuses if s["STATE"] == NavState.REACHED]
    assert depths[:2] == [2, 1]
    assert set(depths[2:]) == {0}
    for goal_id, goal in enumerate(SQUARE, start=1):
        d_m, dh_rad = pose_error(rig.truth_at_reached[goal_id], goal)
        assert d_m < TRUTH_TOL_M, (goal_id, d_m, dh_rad)
        assert dh_rad < TRUTH_TOL_RAD, (goal_id, d_m, dh_rad)
    d_m, dh_rad = pose_error(rig.onboard_pose(), SQUARE[-1])  # settled, as the firmware sees it
    assert d_m < TOL_M
    assert dh_rad < TOL_RAD
    d_m, dh_rad = pose_error(truth_pose(rig), SQUARE[-1])
    assert d_m < TRUTH_TOL_M
    assert dh_rad < TRUTH_TOL_RAD
    last = statuses[-1]
    assert last["STATE"] == NavState.REACHED
    assert last["DISTANCE"] < TOL_M
    assert abs(last["HEADING_ERROR"]) < TOL_RAD


def test_closed_loop_motor_commands_every_20_ms_then_zero_then_silence(rig: LockstepNav) -> None:
    rig.goal(0.3, 0.0, None, goal_id=4)
    rig.run_until_done()
    ticks = [t for t, _ in rig.of("MOTOR_CMD")]
    assert ticks
    assert all(b - a == 2 for a, b in itertools.pairwise(ticks))
    commands = [(c["LEFT_SPEED"], c["RIGHT_SPEED"]) for _, c in rig.of("MOTOR_CMD")]
    assert commands[-nav.ZERO_CMD_PERIODS :] == [(0, 0)] * nav.ZERO_CMD_PERIODS
    assert max(c[0] for c in commands) <= nav.V_MAX_MM_S / 1000
    assert rig.ticks - ticks[-1] > 50  # silent for the last second
    reached = next(t for t, s in rig.of("NAV_STATUS") if s["STATE"] == NavState.REACHED)
    assert ticks[-nav.ZERO_CMD_PERIODS] == reached  # zero from the tick the goal is reached


def test_closed_loop_full_queue_is_nacked_and_stop_halts(rig: LockstepNav) -> None:
    for k in range(nav.NAV_QUEUE_SLOTS + 1):
        rig.goal(2.0 + k, 0.0, None, goal_id=k + 1, mode=NavMode.GO_TO_GOAL)
    gos = [a for _, a in rig.of("ODOM_ACK") if a["REQUEST_FIELD"] == NavGoalField.GO]
    assert [a["RESULT"] for a in gos] == [0] * nav.NAV_QUEUE_SLOTS + [1]
    choices = DB.get_message_by_name("ODOM_ACK").get_signal_by_name("REASON").choices
    assert choices is not None
    assert choices[gos[-1]["REASON"]] == "QUEUE_FULL"
    rig.run(1.0)
    assert rig.vehicle.wheel_speeds_mps()[0] > 0.2
    rig.stop()
    stop_tick = rig.ticks - 1
    rig.run(1.5)
    after = [(c["LEFT_SPEED"], c["RIGHT_SPEED"]) for t, c in rig.of("MOTOR_CMD") if t >= stop_tick]
    assert after == [(0, 0)] * nav.ZERO_CMD_PERIODS
    assert max(map(abs, rig.vehicle.wheel_speeds_mps())) < 1e-6
    status = rig.of("NAV_STATUS")[-1][1]
    assert (status["STATE"], status["QUEUE_DEPTH"]) == (NavState.STOPPED, 0)
    x_before = rig.vehicle.truth().x_m
    rig.run(0.5)
    assert abs(rig.vehicle.truth().x_m - x_before) < 1e-9  # at rest (the motors' tail decays)
    assert rig.reached_ids() == []


def test_closed_loop_replace_drops_the_path(rig: LockstepNav) -> None:
    rig.goal(1.0, 0.0, None, goal_id=1)
    rig.goal(2.0, 0.0, None, goal_id=2)
    rig.run(1.0)
    rig.goal(0.0, 0.2, 90.0, goal_id=3, append=False)
    rig.run_until_done()
    assert rig.reached_ids() == [3]
    d_m, dh_rad = pose_error(rig.onboard_pose(), (0.0, 0.2, 90.0))
    assert d_m < TOL_M
    assert dh_rad < TOL_RAD


def test_systematic_errors_show_in_the_truth_not_on_board() -> None:
    """With E_d = 1.002 and E_b = 1.01 the firmware still reaches every goal by its own
    odometry, while the truth ends much farther from the goal than without the errors."""
    ends: dict[str, tuple[float, float]] = {}
    for name, errors in (("none", ErrorModel()), ("ed_eb", ErrorModel(ed=1.002, eb=1.01))):
        r = LockstepNav(errors)
        try:
            r.run(0.1)
            for goal_id, goal in enumerate(SQUARE, start=1):
                r.goal(*goal, goal_id=goal_id)
            r.run_until_done()
            assert r.reached_ids() == [1, 2, 3]
            d_m, dh_rad = pose_error(r.onboard_pose(), SQUARE[-1])
            assert d_m < TOL_M
            assert dh_rad < TOL_RAD
            ends[name] = pose_error(truth_pose(r), SQUARE[-1])
        finally:
            r.close()
    assert ends["none"][0] < TRUTH_TOL_M
    assert ends["none"][1] < TRUTH_TOL_RAD
    assert ends["ed_eb"][0] > 3 * TRUTH_TOL_M
    assert ends["ed_eb"][1] > 2 * TRUTH_TOL_RAD


def test_ecu_status_page_5_counts_nav_goal_frames(rig: LockstepNav) -> None:
    rig.goal(0.0, 0.0, None, goal_id=1)
    rig.run(1.1)  # every rotating page has gone out at least once since
    pages = [s for _, s in rig.of("ODOM_STATUS") if s["PAGE"] == fr.StatusPage.E2E_NAV_GOAL]
    assert pages
    assert pages[-1]["NAV_GOAL_E2E_OK"] == 3
    assert pages[-1]["NAV_GOAL_E2E_CRC_ERROR"] == 0


def test_ecu_aborts_when_the_encoders_fall_silent(rig: LockstepNav) -> None:
    rig.goal(1.0, 0.0, None, goal_id=1)
    rig.run(0.5)
    ecu = rig.board.ecu
    for _ in range(20):  # the firmware alone: no encoder frame reaches it
        rig.clock.advance_to(rig.ticks * TICK_S)
        ecu.tick()
        rig.ticks += 1
    assert ecu.nav.state is NavState.ABORTED
    assert (ecu.nav.left_mm_s, ecu.nav.right_mm_s) == (0, 0)
