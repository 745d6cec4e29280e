"""The firmware never reports OK while its pose or twist is wrong: gaps, stalls, overflows,
implausible steps and counter restarts, through the HAL, decoded with cantools.

Expected values come from the float robot geometry (``tests.odo_helpers.geometry``) or from a twin
firmware fed the same genuine steps, never from the code under test.
"""

from __future__ import annotations

import math

import pytest

from odocan.firmware import frames as fr
from odocan.firmware.ecu import (
    MAX_WHEEL_SPEED_MM_S,
    RECOVERY_FRAMES,
    RESYNC_FRAMES,
    WATCHDOG_TICKS,
)
from odocan.firmware.errors import ErrorFlag, ErrorMask, Reason, State
from odocan.firmware.hal import MAILBOX_SLOTS, TICK_PERIOD_US
from odocan.sim import frames as sf
from tests import host_frames as hf
from tests.dbc_typed import choices
from tests.odo_helpers import geometry, params
from tests.test_ecu import DB, RecordingHal, Rig

COUNTS_PER_PERIOD = 5  # pmir: 5 x 0.942 mm per 10 ms = 0.471 m/s


class TimedRig(Rig):
    """``Rig`` whose ticks carry the board's microsecond timer, so time can pass without ticks."""

    def __init__(self, integrator: str = "exact") -> None:
        super().__init__(params(integrator))
        self.now_us = 0

    def tick(self, periods: int = 1) -> None:
        """Let ``periods`` pass on the timer, then run one tick."""
        self.now_us += periods * TICK_PERIOD_US
        self.ecu.tick(self.now_us)

    def step(self, d_left: int = COUNTS_PER_PERIOD, d_right: int = COUNTS_PER_PERIOD) -> None:
        """One encoder period with its frame received."""
        self.ecu.isr_can_rx(fr.WHEEL_ENCODERS_ID, self.encoders(d_left, d_right))
        self.tick()

    def forged(self, left: int, right: int) -> bytes:
        """A valid frame (next COUNTER, good CRC) carrying counts the motors never had."""
        data = sf.pack_wheel_encoders(self.counter, left & 0xFFFF, right & 0xFFFF)
        self.counter = (self.counter + 1) % 16
        return data

    def reason(self) -> Reason:
        """The ECU's reason now, read afresh like ``Rig.state()``."""
        return self.ecu.reason

    def summary(self) -> dict[str, int]:
        """The last ODOM_STATUS summary page, raw values."""
        return [s for s in self.hal.decoded("ODOM_STATUS") if s["PAGE"] == 0][-1]


def _speed_mm_s(counts: int) -> int:
    """The rim speed of ``counts`` per 10 ms period on pmir, mm/s (float geometry, rounded)."""
    return round(counts * geometry(params("exact")).m_per_count_left / 0.01 * 1000)


@pytest.mark.parametrize("lost", [16, 31, 100])
def test_twist_is_right_after_a_gap_of_lost_frames(lost: int) -> None:
    rig = TimedRig("euler")
    for _ in range(20):
        rig.step()
    for _ in range(lost):  # the frames are lost on the bus; the firmware keeps ticking
        rig.encoders(COUNTS_PER_PERIOD, COUNTS_PER_PERIOD)
        rig.tick()
    sent_before = len(rig.hal.sent)
    named = rig.counter
    rig.step()  # the first frame after the gap
    if (lost + 1) % 16 == 0:  # its COUNTER came round to the last one's: E2E REPEATED, refused
        assert rig.ecu.rx_encoders.count_repeated == 1
        named = rig.counter
        rig.step()  # so the step spans the gap and one period more
    rig.tick()  # a tick without a frame: the twist goes out (20 ms schedule)
    after = RecordingHal()
    after.sent = rig.hal.sent[sent_before:]
    twists = [t for t in after.decoded("ODOM_TWIST") if t["ENC_COUNTER"] == named]
    assert twists
    assert twists[0]["LINEAR_VEL"] == _speed_mm_s(COUNTS_PER_PERIOD)
    assert twists[0]["ANGULAR_VEL"] == 0
    assert not rig.ecu.errors.has(ErrorFlag.SATURATION)
    g = geometry(rig.ecu.params)
    steps = 19 + lost + 1 + int((lost + 1) % 16 == 0)
    assert rig.ecu.odometry.x_q40_m / 2**40 == pytest.approx(
        steps * COUNTS_PER_PERIOD * g.m_per_count_left, abs=1e-9
    )


def test_a_stalled_firmware_reports_lost_time_and_keeps_the_distance() -> None:
    rig = TimedRig("euler")
    for _ in range(20):
        rig.step()
    assert rig.state() is State.OK
    stall = 200  # a 2 s SIGSTOP: no tick and no ISR runs; the motors go on turning
    held = [rig.encoders(COUNTS_PER_PERIOD, COUNTS_PER_PERIOD) for _ in range(3)]
    for _ in range(stall - 3):  # beyond the controller's 3-frame FIFO: overrun
        rig.encoders(COUNTS_PER_PERIOD, COUNTS_PER_PERIOD)
    for data in held:  # the ISR runs on resume: the FIFO's oldest frames
        rig.ecu.isr_can_rx(fr.WHEEL_ENCODERS_ID, data)
    rig.tick(stall)
    assert rig.state() is State.DEGRADED
    assert rig.reason() is Reason.TIME_LOST
    assert rig.ecu.errors.has(ErrorFlag.TIME_LOST)
    assert rig.ecu.periods_lost == stall - 1
    rig.step()  # the first fresh frame: 198 periods after the last held one
    assert rig.ecu.frames_implausible == 0
    assert rig.ecu.twist.linear_mm_s == _speed_mm_s(COUNTS_PER_PERIOD)
    g = geometry(rig.ecu.params)
    assert rig.ecu.odometry.x_q40_m / 2**40 == pytest.approx(
        (19 + stall + 1) * COUNTS_PER_PERIOD * g.m_per_count_left, abs=1e-9
    )
    for _ in range(RECOVERY_FRAMES - 1):
        rig.step()
    # The 198 periods merged into one step: their path is unknowable (exact here, where the
    # wheels ran steadily, but the firmware cannot know it): latched until a set-pose.
    assert rig.state() is State.DEGRADED
    assert rig.reason() is Reason.POSE_UNCERTAIN
    assert rig.ecu.errors.has(ErrorFlag.TIME_LOST)  # sticky
    assert rig.ecu.errors.has(ErrorFlag.POSE_UNCERTAIN)  # sticky


def test_uptime_and_the_watchdog_count_time_not_ticks() -> None:
    rig = TimedRig()
    rig.step()
    rig.tick(300)  # 3 s on the timer, one tick run
    assert rig.ecu.time_periods == 301
    assert rig.state() is State.DEGRADED
    assert rig.reason() is Reason.TIME_LOST
    for _ in range(9):
        rig.tick()
    status = [s for s in rig.hal.decoded("ODOM_STATUS") if s["PAGE"] == 0]
    assert status[-1]["UPTIME"] == 3
    assert status[-1]["REASON"] == Reason.ENCODER_TIMEOUT  # then the watchdog's own cause
    assert choices(DB, "ODOM_STATUS", "REASON")[Reason.ENCODER_TIMEOUT] == "ENCODER_TIMEOUT"


def test_a_short_late_tick_is_not_lost_time() -> None:
    rig = TimedRig()
    for _ in range(5):
        rig.step()
    rig.ecu.isr_can_rx(fr.WHEEL_ENCODERS_ID, rig.encoders(5, 5))
    rig.tick(WATCHDOG_TICKS - 1)
    assert rig.state() is State.OK
    assert not rig.ecu.errors.has(ErrorFlag.TIME_LOST)


def test_mailbox_overflow_degrades_with_its_reason_then_recovers() -> None:
    rig = TimedRig()
    for _ in range(5):
        rig.step()
    for _ in range(MAILBOX_SLOTS + 1):
        rig.ecu.isr_can_rx(0x555, bytes(8))
    rig.tick()
    assert rig.state() is State.DEGRADED
    assert rig.reason() is Reason.MAILBOX_OVERFLOW
    for _ in range(RECOVERY_FRAMES):
        rig.step()
    assert rig.state() is State.OK


def _bound_counts(p_integrator: str = "exact") -> int:
    """ceil(v_max T / c) + 1 in float: the largest plausible step of one period on pmir."""
    c = geometry(params(p_integrator)).m_per_count_left
    return math.ceil(MAX_WHEEL_SPEED_MM_S * 1e-3 * 0.01 / c) + 1


def test_the_plausibility_bound_is_exact_at_standstill() -> None:
    bound = _bound_counts()
    rig = TimedRig()
    for _ in range(5):
        rig.step(0, 0)
    rig.step(bound, -bound)  # the fastest possible spin: accepted
    assert rig.state() is State.OK
    heading = rig.ecu.odometry.heading_bam64
    rig.ecu.isr_can_rx(fr.WHEEL_ENCODERS_ID, rig.forged(rig.left + bound + 1, rig.right))
    rig.tick()
    assert rig.state() is State.DEGRADED
    assert rig.reason() is Reason.IMPLAUSIBLE_STEP
    assert rig.ecu.odometry.heading_bam64 == heading  # not integrated
    assert rig.ecu.frames_implausible == 1


def test_forged_frames_move_nothing_and_genuine_ones_go_on() -> None:
    rig = TimedRig()
    twin = TimedRig()
    for r in (rig, twin):
        for _ in range(10):
            r.step(5, 7)
    for left, right in ((40_000, 123), (9_000, 61_000), (rig.left + 999, rig.right)):
        rig.ecu.isr_can_rx(fr.WHEEL_ENCODERS_ID, rig.forged(left, right))
        rig.tick()
        twin.encoders(0, 0)  # keep the twin's COUNTER in step; its frame is lost
        twin.tick()
        for r in (rig, twin):
            r.step(5, 7)
    assert rig.ecu.frames_implausible == 3
    assert rig.ecu.odometry.x_q40_m == twin.ecu.odometry.x_q40_m
    assert rig.ecu.odometry.heading_bam64 == twin.ecu.odometry.heading_bam64
    assert not rig.ecu.errors.has(ErrorFlag.COUNTER_RESET)


def test_a_counter_restart_is_re_primed_not_integrated() -> None:
    rig = TimedRig()
    twin = TimedRig()
    for r in (rig, twin):
        for _ in range(30):
            r.step(5, 7)
    before = rig.ecu.odometry.x_q40_m
    rig.left = rig.right = 0  # the motor controller rebooted: its counters restart
    rig.step(5, 7)
    twin.step(0, 0)  # the step across the restart is unknowable: the twin loses it too
    for _ in range(RESYNC_FRAMES - 1):
        for r in (rig, twin):
            r.step(5, 7)
    assert rig.ecu.errors.has(ErrorFlag.COUNTER_RESET)
    assert rig.state() is State.DEGRADED
    assert rig.reason() is Reason.COUNTER_RESET
    assert rig.ecu.odometry.x_q40_m != before
    for _ in range(2 * RECOVERY_FRAMES):
        for r in (rig, twin):
            r.step(5, 7)
    assert rig.state() is State.DEGRADED  # the step across the restart is lost: not OK
    assert rig.summary()["REASON"] == Reason.COUNTER_RESET
    assert abs(rig.ecu.odometry.x_q40_m - twin.ecu.odometry.x_q40_m) < 2**40 * 1e-9
    assert abs(rig.ecu.odometry.y_q40_m - twin.ecu.odometry.y_q40_m) < 2**40 * 1e-9
    assert rig.ecu.odometry.heading_bam64 == twin.ecu.odometry.heading_bam64


def test_a_pose_set_after_a_counter_restart_lets_the_firmware_recover() -> None:
    rig = TimedRig()
    for _ in range(30):
        rig.step(5, 7)
    rig.left = rig.right = 0
    for _ in range(RESYNC_FRAMES + RECOVERY_FRAMES):
        rig.step(5, 7)
    assert rig.reason() is Reason.COUNTER_RESET
    rig.ecu.isr_can_rx(
        fr.ODOM_SET_POSE_ID, hf.pack_odom_set_pose(0, fr.SetPoseField.APPLY, 0, ErrorMask())
    )
    rig.step(5, 7)
    for _ in range(RECOVERY_FRAMES):
        rig.step(5, 7)
    assert rig.state() is State.OK
    assert rig.reason() is Reason.NONE


def test_firmware_time_follows_a_jittery_timer_without_drift() -> None:
    rig = TimedRig()
    jitter_us = [0, 4_000, -4_900, 4_900, 3_000, -3_000] * 50  # ticks released early and late
    for k, j in enumerate(jitter_us, 1):
        rig.ecu.tick(k * TICK_PERIOD_US + j)
    assert rig.ecu.time_periods == len(jitter_us)
    assert not rig.ecu.errors.has(ErrorFlag.TIME_LOST)


def _later_cause(rig: TimedRig, cause: str) -> None:
    """One more cause of DEGRADED, raised while COUNTER_RESET waits for a pose."""
    if cause == "overflow":
        for _ in range(MAILBOX_SLOTS + 1):
            rig.ecu.isr_can_rx(0x555, bytes(8))
        rig.tick()
    elif cause == "stall":
        rig.tick(WATCHDOG_TICKS + 5)  # the MCU was stopped: time passed without ticks
    elif cause == "implausible":
        rig.ecu.isr_can_rx(fr.WHEEL_ENCODERS_ID, rig.forged(rig.left + 9_000, rig.right))
        rig.tick()
    else:  # encoder timeout: the frames stop, the firmware keeps ticking
        for _ in range(WATCHDOG_TICKS + 2):
            rig.encoders(0, 0)
            rig.tick()


@pytest.mark.parametrize("cause", ["overflow", "stall", "implausible", "timeout"])
def test_a_later_cause_does_not_hide_a_counter_restart(cause: str) -> None:
    """COUNTER_RESET asks for a pose (ODOM_SET_POSE APPLY); a later cause must not replace it
    and let the firmware report OK, five good frames later, on a pose that lost continuity."""
    rig = TimedRig()
    for _ in range(30):
        rig.step(5, 7)
    rig.left = rig.right = 0  # the motor controller rebooted
    for _ in range(RESYNC_FRAMES + 2):
        rig.step(5, 7)
    assert rig.ecu.reason is Reason.COUNTER_RESET
    _later_cause(rig, cause)
    assert rig.ecu.state is State.DEGRADED
    for _ in range(3 * RECOVERY_FRAMES):
        rig.step(5, 7)
    assert rig.ecu.state is State.DEGRADED
    assert rig.ecu.reason is Reason.COUNTER_RESET
    assert rig.summary()["REASON"] == Reason.COUNTER_RESET
    rig.ecu.isr_can_rx(
        fr.ODOM_SET_POSE_ID, hf.pack_odom_set_pose(0, fr.SetPoseField.APPLY, 0, ErrorMask())
    )
    for _ in range(RECOVERY_FRAMES + 1):
        rig.step(5, 7)
    assert rig.state() is State.OK
    assert rig.reason() is Reason.NONE
