"""ODOM_TWIST's speeds: the steps integrated in a tick, over the firmware time they cover.

Each accepted step adds its travel (Q20 m) and heading change (Q30 rad) to this tick's sums (i64,
saturated to +-2^32: 4096 m and 4 rad), and its sample periods (``EncoderInput._step_periods``:
the COUNTER advance, whole counter cycles from firmware time) to their span. At the end of the
drain the speeds are the sums over that span, not over ticks: lost frames and a late frame
(accepted a tick after its period: one step in a tick of two periods, then two steps in a tick
of one) give the true mean speed. After a stall the steps are summed over two ticks and divided
by the firmware time since the last sample before it, as the backlog's sample times are unknown.
"""

from __future__ import annotations

from odocan.firmware.config import ENCODER_PERIOD_US as ENCODER_PERIOD_US
from odocan.firmware.config import TWO_PI_Q60
from odocan.firmware.errors import ErrorMask
from odocan.firmware.fixmath import U16_MAX, mul_shr_round_i64, sat_range
from odocan.firmware.odometry import Odometry
from odocan.firmware.uncertainty import PoseUncertainty

TWO_PI_Q30 = (TWO_PI_Q60 + (1 << 29)) >> 30  # one turn in Q30 rad (< 2^33)
TWIST_SUM_MAX = 1 << 32  # one tick's summed steps saturate at 4096 m (Q20) and 4 rad (Q30)
TWIST_SUM_MIN = -TWIST_SUM_MAX
PERIODS_MAX = U16_MAX  # the speeds' dt saturates here (655 s; encoders.STEP_PERIODS_MAX)


class Twist:
    """This tick's summed steps and the last speeds (C: two i64 sums, a u8 count, two i32)."""

    def __init__(
        self, odometry: Odometry, errors: ErrorMask, uncertainty: PoseUncertainty | None = None
    ) -> None:
        """``uncertainty``: told every step that spans more than one period (None: no one)."""
        self._odometry = odometry
        self._errors = errors
        self._uncertainty = uncertainty
        self.tick_ds_q20_m = 0  # i64, saturated to +-2^32 (4096 m)
        self.tick_dheading_q30_rad = 0  # i64, saturated to +-2^32 (4 rad)
        self.steps = 0  # steps summed since the last update
        self.tick_periods = 0  # u16, saturated: the sample periods the summed steps span
        self.carried = False  # the sums hold steps of a tick that lost time
        self.linear_mm_s = 0  # i32: ODOM_TWIST LINEAR_VEL before its i16 saturation
        self.angular_mrad_s = 0  # i32: ODOM_TWIST ANGULAR_VEL before its i16 saturation

    def sum_step(self, periods: int) -> None:
        """Add the step just integrated, spanning ``periods`` sample periods, to this tick's sums
        (Q20 m, Q30 rad; i64, saturated: ``sat_range`` only when a sum leaves +-TWIST_SUM_MAX);
        a step merged across more than one period adds its bound to the pose's uncertainty."""
        odo = self._odometry
        errors = self._errors
        if periods > 1 and self._uncertainty is not None:
            self._uncertainty.merged_step(
                periods, odo.last_ds_q49_m, odo.last_dheading_bam64, odo.last_dheading_turns
            )
        dheading_q30_rad = (  # the signed read, plus the step's whole turns (< 2^62)
            mul_shr_round_i64(odo.last_dheading_bam64, TWO_PI_Q60, 94, errors)
            + odo.last_dheading_turns * TWO_PI_Q30
        )
        ds_q20_m = self.tick_ds_q20_m + (odo.last_ds_q49_m >> 29)
        if not TWIST_SUM_MIN <= ds_q20_m <= TWIST_SUM_MAX:
            ds_q20_m = sat_range(ds_q20_m, TWIST_SUM_MIN, TWIST_SUM_MAX, errors)
        self.tick_ds_q20_m = ds_q20_m
        dheading_q30_rad += self.tick_dheading_q30_rad
        if not TWIST_SUM_MIN <= dheading_q30_rad <= TWIST_SUM_MAX:
            dheading_q30_rad = sat_range(dheading_q30_rad, TWIST_SUM_MIN, TWIST_SUM_MAX, errors)
        self.tick_dheading_q30_rad = dheading_q30_rad
        self.steps += 1
        tick_periods = self.tick_periods + periods
        self.tick_periods = tick_periods if tick_periods < PERIODS_MAX else PERIODS_MAX

    def end_drain(self, time_lost_now: bool, periods_since_sample: int) -> None:
        """After the drain: the speeds of this tick's steps, unless the tick lost time (a stall's
        backlog: summed on, over the next tick, and then over ``periods_since_sample``)."""
        if not self.steps:
            return
        if time_lost_now:
            self.carried = True
        elif self.carried:
            self.update(max(periods_since_sample, 1))
        else:
            self.update(self.tick_periods)

    def update(self, periods: int) -> None:
        """Speeds over this tick's steps, which cover ``periods`` (1 .. PERIODS_MAX). Products
        < 2^32 * 10^9 < 2^63. The sums restart."""
        dt_us = periods * ENCODER_PERIOD_US
        # div_round_i64 in line (every tick with steps): |num| + half rounded down, signed back
        num, den = self.tick_ds_q20_m * 1_000_000_000, dt_us << 20
        speed = (abs(num) + (den >> 1)) // den
        self.linear_mm_s = speed if num >= 0 else -speed
        num, den = self.tick_dheading_q30_rad * 1_000_000_000, dt_us << 30
        speed = (abs(num) + (den >> 1)) // den
        self.angular_mrad_s = speed if num >= 0 else -speed
        self.tick_ds_q20_m = 0
        self.tick_dheading_q30_rad = 0
        self.steps = 0
        self.tick_periods = 0
        self.carried = False
